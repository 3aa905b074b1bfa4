// Serialised FMU states (fmi2SerializeFMUstate, fmi2DeSerializeFMUstate); the format is in
// README.md of this folder. A model's part is its variables (the table) and its internal state
// (state_fields(), model.hpp), both written and read by the same lists.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

#include "fmi2_support.hpp"
#include "instance.hpp"
#include "log_text.hpp"
#include "state_stream.hpp"
#include "variable.hpp"

namespace fmi {

namespace glue {

inline constexpr char kStateMagic[8] = {'I', 'P', 'M', 'S', 'M', 'F', 'S', 'T'};
// 4: IpmsmDrive's part no longer repeats its models' parameters (the drive's own variables, checked
// here, hold them), and every field is checked as it is read (state_stream.hpp)
inline constexpr std::uint32_t kStateFormat = 4;

// The variables of a model that the standard s has (variable.hpp, fmi3_only), each as its type's
// index then its value (an array: its count, then its elements).
template <class M>
std::size_t state_variable_count(const Standard& s) {
    std::size_t n = 0;
    for (const auto& v : variables<M>()) n += (s.time_variable || !fmi3_only(v)) ? 1 : 0;
    return n;
}

template <class M>
void write_variables(StateWriter& w, const M& m, const Standard& s) {
    w.put<std::uint64_t>(state_variable_count<M>(s));
    for (const auto& v : variables<M>()) {
        if (!s.time_variable && fmi3_only(v)) continue;
        w.put<std::uint8_t>(static_cast<std::uint8_t>(v.member.index()));
        std::visit(
            [&](const auto& a) {
                const auto x = a.read(m);
                using T = std::decay_t<decltype(x)>;
                if constexpr (std::is_same_v<T, std::string>)
                    w.put_string(x);
                else if constexpr (std::is_same_v<T, bool>)
                    w.put<std::uint8_t>(x ? 1 : 0);
                else if constexpr (std::is_same_v<T, int>)
                    w.put<std::int32_t>(x);
                else if constexpr (std::is_same_v<T, std::uint64_t>)
                    w.put<std::uint64_t>(x);
                else if constexpr (std::is_same_v<T, std::vector<double>>) {
                    w.put<std::uint64_t>(x.size());
                    for (double e : x) w.put<double>(e);
                } else
                    w.put<double>(x);
            },
            v.member);
    }
}

// Reads what write_variables() wrote into m; throws fmi::Error naming the variable. Either
// standard reads the other's states: one without FMI 3.0's own variables leaves m's as they are,
// one with them sets them in m too (an FMI 2.0 FMU then refuses it unless they are its values,
// the defaults: deserialise() compares the fixed parameters).
template <class M>
void read_variables(StateReader& r, M& m, const char* what, const Standard& s) {
    const auto& vars = variables<M>();
    const auto n = r.get<std::uint64_t>();
    if (n != state_variable_count<M>(fmi2_standard) && n != state_variable_count<M>(fmi3_standard))
        throw Error(std::string(what) + " has " + std::to_string(n) + " variables; this FMU has " +
                    std::to_string(state_variable_count<M>(s)));
    const bool with_fmi3_only = n == vars.size();
    for (const auto& v : vars) {
        if (!with_fmi3_only && fmi3_only(v)) continue;
        if (r.get<std::uint8_t>() != v.member.index())
            throw Error(std::string(what) + ": variable " + v.name + " has another type");
        std::visit(
            [&](const auto& a) {
                using T = std::decay_t<decltype(a.read(m))>;
                if constexpr (std::is_same_v<T, std::string>)
                    a.write(m, r.get_string());
                else if constexpr (std::is_same_v<T, bool>)
                    a.write(m, r.get<std::uint8_t>() != 0);
                else if constexpr (std::is_same_v<T, int>)
                    a.write(m, r.get<std::int32_t>());
                else if constexpr (std::is_same_v<T, std::uint64_t>)
                    a.write(m, r.get<std::uint64_t>());
                else if constexpr (std::is_same_v<T, std::vector<double>>) {
                    std::vector<double> x = r.get_doubles();
                    for (double e : x)
                        if (!std::isfinite(e))
                            throw Error(std::string(what) + ": variable " + v.name + " has a value that is not finite");
                    a.write(m, x);
                } else {
                    const double x = r.get<double>();
                    if (!std::isfinite(x)) throw Error(std::string(what) + ": variable " + v.name + " is not finite");
                    a.write(m, x);
                }
            },
            v.member);
    }
}

template <class M>
std::vector<char> serialise(Snapshot<M>& s, const Standard& standard) {
    std::vector<char> out(kStateMagic, kStateMagic + sizeof kStateMagic);
    StateWriter w(out);
    w.put<std::uint32_t>(kStateFormat);
    w.put_string(M::model_identifier);
    w.put_string(M::guid);
    w.put<std::uint8_t>(static_cast<std::uint8_t>(s.phase));
    w.put<double>(s.start_time);
    w.put<double>(s.time);
    write_variables(w, s.model, standard);
    const std::vector<char> block = save_state_fields(s.model);
    w.put_string(std::string(block.begin(), block.end()));
    w.put<std::uint64_t>(fnv1a(out.data(), out.size()));
    return out;
}

// Reads a serialised state made by serialise() for the instance `in`; throws fmi::Error.
template <class M>
std::unique_ptr<Snapshot<M>> deserialise(const Instance<M>& in, const char* data, std::size_t size) {
    const char* what = "the serialised FMU state";
    if (size < sizeof kStateMagic + sizeof(std::uint64_t))
        throw Error(std::string(what) + " is truncated (" + std::to_string(size) + " bytes)");
    if (std::memcmp(data, kStateMagic, sizeof kStateMagic) != 0)
        throw Error(std::string(what) + " is not one (it does not start with the ipmsm-fmu state header)");
    std::uint64_t stored;
    std::memcpy(&stored, data + size - sizeof stored, sizeof stored);
    if (stored != fnv1a(data, size - sizeof stored))
        throw Error(std::string(what) + " is corrupt or truncated (checksum mismatch)");
    StateReader r(data + sizeof kStateMagic, size - sizeof kStateMagic - sizeof stored);
    if (const auto format = r.get<std::uint32_t>(); format != kStateFormat)
        throw Error(std::string(what) + " has format " + std::to_string(format) + "; this FMU reads format " +
                    std::to_string(kStateFormat));
    const std::string id = r.get_string(), guid = r.get_string();
    if (id != M::model_identifier || guid != M::guid)
        throw Error(std::string(what) + " belongs to " + utf8_excerpt(id, 100) + " " + utf8_excerpt(guid, 100) +
                    ", not to " + M::model_identifier + " " + M::guid);
    const auto phase_value = r.get<std::uint8_t>();
    if (phase_value < static_cast<std::uint8_t>(Phase::instantiated) ||
        phase_value > static_cast<std::uint8_t>(Phase::terminated))
        throw Error(std::string(what) + " has an invalid instance state (" + std::to_string(phase_value) + ")");
    const auto phase = static_cast<Phase>(phase_value);
    const double start_time = r.get<double>(), time = r.get<double>();
    if (!std::isfinite(start_time) || !std::isfinite(time)) throw Error(std::string(what) + " has a non-finite time");

    M m = in.model;
    read_variables(r, m, what, in.standard);
    // Validated as fmi2SetReal/Integer validate them: a state is input, not proof (its checksum
    // guards against accidents, not against edits).
    for (const auto& v : variables<M>()) {
        if (v.causality != Causality::input && v.causality != Causality::parameter &&
            v.causality != Causality::structural_parameter)
            continue;
        const Type t = type_of(v);
        if (t == Type::RealArray && value_of<std::vector<double>>(m, v).size() != value_count(m, v))
            throw Error(std::string(what) + ": " + v.name + " has " +
                        std::to_string(value_of<std::vector<double>>(m, v).size()) + " values, not " +
                        count_text(m, v) + "; not restored");
        if (t != Type::Real && t != Type::Integer && t != Type::UInt64) continue;
        const double x = t == Type::Real      ? value_of<double>(m, v)
                         : t == Type::Integer ? value_of<int>(m, v)
                                              : static_cast<double>(value_of<std::uint64_t>(m, v));
        if (const std::string why = range_error(v, x); !why.empty())
            throw Error(std::string(what) + ": " + why + "; not restored");
    }
    std::string mismatch;
    for (const auto& v : variables<M>()) {
        if (v.causality == Causality::input || is_computed(v.causality) || v.variability != Variability::fixed)
            continue;
        if (type_of(v) == Type::RealArray) {  // compared as values, named without them
            if (value_of<std::vector<double>>(m, v) != value_of<std::vector<double>>(in.model, v))
                mismatch += std::string(mismatch.empty() ? "" : ", ") + v.name + " differs";
            continue;
        }
        const std::string there = value_text(m, v), here = value_text(in.model, v);
        if (there != here)
            mismatch +=
                std::string(mismatch.empty() ? "" : ", ") + v.name + " = " + there + " there, " + here + " here";
    }
    if (!mismatch.empty())
        throw Error(std::string(what) + " was saved with other fixed parameters than this instance has (" + mismatch +
                    "); set the same parameters before " + in.standard.deserialize_fmu_state);

    const bool saved_initialised = phase == Phase::step_complete || phase == Phase::terminated;
    const bool here_initialised = in.phase == Phase::step_complete || in.phase == Phase::terminated;
    if (saved_initialised && !here_initialised) {
        // The model's data (loaded by exit_initialization) is not in the state: load it with the
        // saved parameters, then put the saved values back.
        M initialised = m;
        initialised.exit_initialization();
        for (const auto& v : variables<M>()) copy_value(m, initialised, v);
        m = std::move(initialised);
    }

    const std::string block = r.get_string();
    load_state_fields(m, block.data(), block.size());
    if (!r.at_end()) throw Error(std::string(what) + " has trailing bytes");
    return std::unique_ptr<Snapshot<M>>(new Snapshot<M>{std::move(m), phase, start_time, time, {}});
}

}  // namespace glue
}  // namespace fmi
