// The functions FMI 2.0 and FMI 3.0 co-simulation share, for a model M and the standard S an FMU
// speaks, as static members of Functions<M, S>; fmi2_functions.hpp and fmi3_functions.hpp add
// each standard's own, and fmi2_entry_points.inc, fmi3_entry_points.inc export them under their C
// names. Every function with an instance goes through guarded(), the one exception boundary.
// The glue's own status type is fmi2Status (fmi3Status has the same values). README.md in this
// folder specifies what each function accepts and refuses.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <limits>
#include <memory>
#include <new>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "fmi2Functions.h"
#include "fmi2_support.hpp"
#include "fmu_state.hpp"
#include "instance.hpp"
#include "model.hpp"
#include "standard.hpp"
#include "variable.hpp"

namespace fmi::glue {

// The value of an enum argument from C, read without assuming it is one of the enumerators.
template <class E>
int enum_value(const E& e) {
    std::underlying_type_t<E> v;
    std::memcpy(&v, &e, sizeof v);
    return static_cast<int>(v);
}

template <class M>
Instance<M>* instance_of(void* c, const Standard& s) {
    auto* in = static_cast<Instance<M>*>(c);
    return (in != nullptr && in->tag == Instance<M>::tag_of(s)) ? in : nullptr;
}

// Phases in which each group of functions may be called (FMI 2.0, section 4.2.4).
inline constexpr PhaseMask kAnyButFatal =
    mask(Phase::instantiated, Phase::initialization_mode, Phase::step_complete, Phase::terminated, Phase::error);
inline constexpr PhaseMask kGet =
    mask(Phase::initialization_mode, Phase::step_complete, Phase::terminated, Phase::error);
inline constexpr PhaseMask kSet = mask(Phase::instantiated, Phase::initialization_mode, Phase::step_complete);
inline constexpr PhaseMask kStatus = mask(Phase::step_complete, Phase::terminated);

// The value references of an FMI 2.0 FMU: 0 up to the last variable FMI 2.0 has (variable.hpp,
// fmi3_only).
template <class M>
std::size_t fmi2_variable_count() {
    static const std::size_t n = [] {
        const auto& vars = variables<M>();
        std::size_t k = 0;
        for (std::size_t i = 0; i < vars.size(); ++i)
            if (!fmi3_only(vars[i])) k = i + 1;
        return k;
    }();
    return n;
}

// The variable that vr names, if it has the type of the Get or Set function; else throws. (FMI
// 3.0's independent variable `time`, kTimeValueReference, is read by the Get alone.)
template <class M>
const Variable<M>& variable_of(fmi2ValueReference vr, Type type, const Standard& s) {
    const auto& vars = variables<M>();
    if (s.time_variable && vr == kTimeValueReference)
        throw Error("value reference " + std::to_string(vr) +
                    " is time, the independent variable: it can be read, and only " + s.do_step + " advances it");
    if (vr >= vars.size() || (!s.time_variable && vr >= fmi2_variable_count<M>()))
        throw Error("unknown value reference " + std::to_string(vr) + " (this FMU has 0.." +
                    std::to_string((s.time_variable ? vars.size() : fmi2_variable_count<M>()) - 1) + ")");
    const auto& v = vars[vr];
    if (!s.time_variable && fmi3_only(v))  // FMI 2.0 has no such variable (variable.hpp)
        throw Error("unknown value reference " + std::to_string(vr));
    if (type_of(v) != type && !(type == Type::Real && type_of(v) == Type::RealArray))
        throw Error("value reference " + std::to_string(vr) + " is the " + type_name(type_of(v)) + " " + v.name +
                    ", not " + (type == Type::Integer ? "an " : "a ") + type_name(type));
    return v;
}

// Throws unless a master may set v in phase p: inputs always, fixed parameters until
// ExitInitializationMode, tunable ones always; outputs and locals never.
template <class M>
void check_settable(const Variable<M>& v, Phase p, const Standard& s) {
    if (p == Phase::configuration_mode && v.causality != Causality::structural_parameter)
        throw Error(std::string(v.name) + " is not a structural parameter: in ConfigurationMode only those can be set");
    switch (v.causality) {
        case Causality::input: return;
        case Causality::structural_parameter:
            if (p != Phase::configuration_mode)
                throw Error(std::string(v.name) +
                            " is a structural parameter: it can be set only in ConfigurationMode "
                            "(fmi3EnterConfigurationMode; the instance is in state " +
                            phase_name(p, s.major) + ")");
            return;
        case Causality::parameter:
            if (v.variability == Variability::fixed && p != Phase::instantiated && p != Phase::initialization_mode)
                throw Error(std::string(v.name) + " is a fixed parameter: it can be set only before " +
                            s.exit_initialization_mode + " (the instance is in state " + phase_name(p, s.major) + ")");
            return;
        case Causality::output:
        case Causality::local:
            throw Error(std::string(v.name) + " is " + (v.causality == Causality::output ? "an " : "a ") +
                        causality_name(v.causality) + ": only inputs and parameters can be set");
    }
}

// Whether a step from t continues the last one, which ended at `expected` (the experiment
// started at `start`). Masters that add up their steps, or pass h_k = t_{k+1} - t_k (fmpy,
// libcosim), give exactly `expected`: t + h is the same IEEE operation on both sides, and the
// difference of two close times is exact. Masters that count them (t_k = start + k h,
// numpy.linspace) differ from it by the roundings of five additions and products of numbers no
// larger than |t| + |start|: at most 2.5 eps (|t| + |start|), eps = 2^-52. A tolerance of
// 4 eps (|t| + |start|) accepts all of them and refuses any real gap or overlap: at t = 1.7e9 s
// it is 1.5 us, far below a communication step.
inline bool follows_last_step(double t, double expected, double start) {
    const double scale = std::abs(expected) + std::abs(start);
    return std::abs(t - expected) <= 4.0 * std::numeric_limits<double>::epsilon() * scale;
}

// The one exception boundary: every function with an instance goes through here.
template <class M, const Standard& S, class Body>
fmi2Status guarded(void* c, const char* fn, PhaseMask allowed, Body&& body) noexcept {
    Instance<M>* in = instance_of<M>(c, S);
    if (in == nullptr) return fmi2Error;  // NULL or not an instance of this FMU: nobody to log to
    try {
        if (in->tracing())
            in->log(fmi2OK, LogCategory::all, std::string(fn) + " (state " + phase_name(in->phase, S.major) + ")");
        if (!(mask(in->phase) & allowed)) {
            in->log(fmi2Error, LogCategory::error,
                    std::string(fn) + " is not allowed in state " + phase_name(in->phase, S.major) +
                        " (allowed in: " + mask_text(allowed, S.major) + "); nothing was changed");
            return fmi2Error;
        }
        // A call that completes returns fmi2OK even when the model logged a warning (status
        // fmi2Warning, category logStatusWarning): strict importers (OMSimulator) end the run on
        // fmi2Warning, and a recoverable condition must not stop a drive cycle.
        return body(*in);
    } catch (const std::bad_alloc&) {
        in->phase = Phase::fatal;
        call_logger(in->logger, in->name.c_str(), fmi2Fatal, LogCategory::fatal,
                    std::string(fn) + ": out of memory; only " + S.free_instance + " is possible now");
        return fmi2Fatal;
    } catch (const std::exception& e) {
        in->log(fmi2Error, LogCategory::error, std::string(fn) + ": " + e.what());
        return fmi2Error;
    } catch (...) {
        in->log(fmi2Error, LogCategory::error, std::string(fn) + ": unknown exception (not a std::exception)");
        return fmi2Error;
    }
}

// --- the functions both standards share, for model M ---
template <class M, const Standard& S>
struct Functions {
    using In = Instance<M>;
    // Every state but fatal, FMI 3.0's Configuration Mode too (fmi3SetDebugLogging, fmi3Reset).
    static constexpr PhaseMask kAnyHere = kAnyButFatal | (S.major == 3 ? mask(Phase::configuration_mode) : 0u);

    // A new instance, or nullptr after logging why through `logger`: instantiate() of both standards,
    // given what each checked of its own arguments. `token` is the GUID (FMI 2.0), the
    // instantiationToken (FMI 3.0); `resources` the resources directory ("" if none, then `none`
    // says why).
    static In* create(const char* fn, const char* instance_name, const char* token, const Logger& logger,
                      bool logging_on, const std::string& resources, const std::string& none) noexcept {
        auto refuse = [&](const std::string& why) -> In* {
            call_logger(logger, instance_name, fmi2Error, LogCategory::error, std::string(fn) + ": " + why);
            return nullptr;
        };
        try {
            if (instance_name == nullptr || instance_name[0] == '\0')
                return refuse("instanceName must be a non-empty string");
            if (token == nullptr || std::strcmp(token, M::guid) != 0)
                return refuse(std::string(S.time_variable ? "instantiationToken " : "GUID ") +
                              (token != nullptr ? utf8_excerpt(token, 100) : "(NULL)") + " does not match " + M::guid +
                              " of this binary: use the modelDescription.xml that came with it");
            auto in = std::make_unique<In>(S, instance_name, logger, logging_on, resources);
            if (resources.empty())
                in->log(fmi2Warning, LogCategory::warning,
                        std::string(fn) + ": " + none + ": the model has no resources directory");
            else
                in->log(fmi2OK, LogCategory::events,
                        std::string(fn) + ": resources in " + utf8_excerpt(resources, 300));
            return in.release();
        } catch (const std::exception& e) {
            return refuse(e.what());
        } catch (...) {
            return refuse("unknown exception (not a std::exception)");
        }
    }

    static void free_instance(void* c) noexcept { delete instance_of<M>(c, S); }

    static fmi2Status set_debug_logging(void* c, bool on, std::size_t n, const char* const categories[]) noexcept {
        return guarded<M, S>(c, S.set_debug_logging, kAnyHere, [&](In& in) {
            if (n > 0 && categories == nullptr) throw Error("categories is NULL with nCategories > 0");
            unsigned bits = 0;
            for (std::size_t i = 0; i < n; ++i) {
                const char* name = categories[i];
                unsigned k = 0;
                while (k < log_categories.size() && (name == nullptr || std::strcmp(name, log_categories[k].name) != 0))
                    ++k;
                if (k == log_categories.size()) {
                    std::string known;
                    for (const auto& lc : log_categories) known += std::string(known.empty() ? "" : ", ") + lc.name;
                    throw Error("unknown log category \"" + std::string(name != nullptr ? name : "(NULL)") +
                                "\" (known: " + known + ")");
                }
                bits |= 1u << k;
            }
            in.categories = !on ? 0u : (n == 0 ? default_categories : bits);
            return fmi2OK;
        });
    }

    // The experiment's start (and stop) time: fmi2SetupExperiment, fmi3EnterInitializationMode.
    static void set_experiment(In& in, double start, bool stop_defined, double stop) {
        if (!std::isfinite(start)) throw Error("startTime = " + number_text(start) + " is not finite");
        if (stop_defined && !(std::isfinite(stop) && stop >= start))
            throw Error("stopTime = " + number_text(stop) + " must be finite and >= startTime = " + number_text(start));
        in.start_time = start;
        in.time = start;
    }

    static fmi2Status enter_initialization_mode(void* c) noexcept {
        return guarded<M, S>(c, S.enter_initialization_mode, mask(Phase::instantiated), [&](In& in) {
            in.phase = Phase::initialization_mode;
            return fmi2OK;
        });
    }

    static fmi2Status exit_initialization_mode(void* c) noexcept {
        return guarded<M, S>(c, S.exit_initialization_mode, mask(Phase::initialization_mode), [&](In& in) {
            in.undoable([&] { in.model.exit_initialization(); }, [] { return std::string("initialisation"); });
            in.initial.reset();
            in.phase = Phase::step_complete;
            return fmi2OK;
        });
    }

    static fmi2Status terminate(void* c) noexcept {
        return guarded<M, S>(c, S.terminate, mask(Phase::step_complete), [&](In& in) {
            in.phase = Phase::terminated;
            return fmi2OK;
        });
    }

    static fmi2Status reset(void* c) noexcept {
        return guarded<M, S>(c, S.reset, kAnyHere, [&](In& in) {
            M fresh(in.context);
            using std::swap;
            swap(in.model, fresh);
            in.initial.reset();
            in.phase = Phase::instantiated;
            in.start_time = 0.0;
            in.time = 0.0;
            return fmi2OK;
        });
    }

    // --- values ---
    // FMI 3.0 may also set in ConfigurationMode (structural parameters) and get there.
    static constexpr PhaseMask kSetHere = kSet | (S.major == 3 ? mask(Phase::configuration_mode) : 0u);
    static constexpr PhaseMask kGetHere = kGet | (S.major == 3 ? mask(Phase::configuration_mode) : 0u);

    // The variables vr[] names, checked for the type of the Get or Set (nullptr: FMI 3.0's `time`),
    // and the values they hold: `n_values` is FMI 3.0's nValues (FMI 2.0 passes nvr), one per
    // scalar and an array's elements (its lengths' product, in m).
    static std::vector<const Variable<M>*> named(const M& m, Type type, const fmi2ValueReference vr[], std::size_t nvr,
                                                 bool value_null, std::size_t n_values) {
        auto null_error = [] { return Error("vr[] or value[] is NULL with nvr > 0"); };
        const bool arrays = S.major == 3 && type == Type::Real && has_arrays();
        if (!arrays && n_values != nvr)
            throw Error("nValues = " + std::to_string(n_values) + " but nValueReferences = " + std::to_string(nvr) +
                        ": every variable of this type is a scalar (one value per value reference)");
        std::vector<const Variable<M>*> vars;
        if (nvr == 0 && n_values == 0) return vars;
        if (vr == nullptr || (value_null && nvr > 0)) throw null_error();
        vars.reserve(std::min<std::size_t>(nvr, variables<M>().size() + 1));
        std::size_t count = 0;
        std::string array_counts;  // the arrays' counts, for a message
        for (std::size_t i = 0; i < nvr; ++i) {
            if (S.time_variable && type == Type::Real && vr[i] == kTimeValueReference) {
                vars.push_back(nullptr);
                ++count;
                continue;
            }
            const Variable<M>& v = variable_of<M>(vr[i], type, S);
            vars.push_back(&v);
            const std::size_t n = value_count(m, v);
            count = n > std::numeric_limits<std::size_t>::max() - count ? std::numeric_limits<std::size_t>::max()
                                                                        : count + n;
            if (!v.dimensions.empty() && array_counts.size() < 1000)
                array_counts += (array_counts.empty() ? "" : "; ") + count_text(m, v);
        }
        if (count != n_values)
            throw Error("nValues = " + std::to_string(n_values) + " but nValueReferences = " + std::to_string(nvr) +
                        " name " + std::to_string(count) + " values" +
                        (array_counts.empty() ? std::string(" (one per scalar)")
                                              : " (one per scalar, an array's elements: " + array_counts + ")"));
        return vars;
    }

    static bool has_arrays() {
        static const bool any = [] {
            for (const auto& v : variables<M>())
                if (type_of(v) == Type::RealArray) return true;
            return false;
        }();
        return any;
    }

    template <class C>
    static fmi2Status get(void* c, const char* fn, Type type, const fmi2ValueReference vr[], std::size_t nvr, C value[],
                          std::size_t n_values) noexcept {
        return guarded<M, S>(c, fn, kGetHere, [&](In& in) {
            const auto vars = named(in.model, type, vr, nvr, value == nullptr, n_values);
            if (vars.empty()) return fmi2OK;
            // In Initialization Mode an output or local comes from initial_model().
            const bool init = in.phase == Phase::initialization_mode;
            bool from_initial = false;
            for (const Variable<M>* v : vars) from_initial = from_initial || (init && v && is_computed(v->causality));
            const M& model = from_initial ? in.initial_model() : in.model;
            if constexpr (std::is_same_v<C, fmi2String>) {
                in.strings.resize(nvr);
                for (std::size_t i = 0; i < nvr; ++i) in.strings[i] = value_of<std::string>(model, *vars[i]);
                for (std::size_t i = 0; i < nvr; ++i) value[i] = in.strings[i].c_str();
            } else {
                std::size_t k = 0;  // the next value
                for (const Variable<M>* v : vars) {
                    if constexpr (std::is_same_v<C, fmi2Real>) {
                        if (v == nullptr) {  // FMI 3.0's independent variable: where the instance is in time
                            value[k++] = in.time;
                        } else if (type_of(*v) == Type::RealArray) {
                            for (double x : value_of<std::vector<double>>(model, *v)) value[k++] = x;
                        } else {
                            value[k++] = value_of<double>(model, *v);
                        }
                    } else if constexpr (std::is_same_v<C, std::uint64_t>) {
                        value[k++] = value_of<std::uint64_t>(model, *v);
                    } else if (type == Type::Integer) {
                        value[k++] = value_of<int>(model, *v);
                    } else {
                        value[k++] = value_of<bool>(model, *v) ? fmi2True : fmi2False;
                    }
                }
            }
            return fmi2OK;
        });
    }

    template <class C>
    static fmi2Status set(void* c, const char* fn, Type type, const fmi2ValueReference vr[], std::size_t nvr,
                          const C value[], std::size_t n_values) noexcept {
        return guarded<M, S>(c, fn, kSetHere, [&](In& in) {
            const auto vars = named(in.model, type, vr, nvr, value == nullptr, n_values);
            if (vars.empty()) return fmi2OK;
            std::size_t k = 0;
            for (const Variable<M>* p : vars) {  // validate everything, then write
                if (p == nullptr)
                    throw Error("value reference " + std::to_string(kTimeValueReference) +
                                " is time, the independent variable: it can be read, and only " + S.do_step +
                                " advances it");
                const auto& v = *p;
                check_settable(v, in.phase, S);
                if constexpr (std::is_same_v<C, fmi2String>) {
                    if (value[k] == nullptr) throw Error(std::string(v.name) + ": the value is a NULL string");
                    ++k;
                } else if (type_of(v) == Type::RealArray) {
                    const std::size_t n = value_count(in.model, v);
                    for (std::size_t j = 0; j < n; ++j, ++k) {
                        const double x = static_cast<double>(value[k]);
                        if (!std::isfinite(x) || !in_range(v, x))
                            throw Error(std::string(v.name) + "[" + std::to_string(j) + "]: " + range_error(v, x) +
                                        "; nothing was changed");
                    }
                } else if (type != Type::Boolean) {
                    const double x = static_cast<double>(value[k++]);
                    // (the message is built only on failure: this loop runs for every input of every fmi2SetReal)
                    if (!std::isfinite(x) || !in_range(v, x))
                        throw Error(range_error(v, x) + "; kept " + value_text(in.model, v));
                } else {
                    ++k;
                }
            }
            k = 0;
            for (const Variable<M>* p : vars) {
                const auto& v = *p;
                if constexpr (std::is_same_v<C, fmi2String>) {
                    set_value(in.model, v, std::string(value[k++]));
                } else if constexpr (std::is_same_v<C, fmi2Real>) {
                    if (type_of(v) == Type::RealArray) {
                        const std::size_t n = value_count(in.model, v);
                        set_value(in.model, v, std::vector<double>(value + k, value + k + n));
                        k += n;
                    } else {
                        set_value(in.model, v, static_cast<double>(value[k++]));
                    }
                } else if constexpr (std::is_same_v<C, std::uint64_t>) {
                    set_value(in.model, v, static_cast<std::uint64_t>(value[k++]));
                } else if (type == Type::Integer) {
                    set_value(in.model, v, static_cast<int>(value[k++]));
                } else {
                    set_value(in.model, v, value[k++] != fmi2False);
                }
            }
            if constexpr (std::is_same_v<C, std::uint64_t>) resize_arrays(in.model);
            in.initial.reset();
            return fmi2OK;
        });
    }

    // --- FMU states ---
    static Snapshot<M>& snapshot(In& in, void* s) {
        auto* p = static_cast<Snapshot<M>*>(s);
        if (s == nullptr || in.snapshots.count(p) == 0)
            throw Error("the FMUstate is not one of this instance's (or was freed)");
        return *p;
    }

    static fmi2Status get_fmu_state(void* c, void** state) noexcept {
        return guarded<M, S>(c, S.get_fmu_state, kAnyButFatal & ~mask(Phase::error), [&](In& in) {
            if (state == nullptr) throw Error("FMUstate is NULL");
            if (*state != nullptr) {  // reuse a state returned earlier
                Snapshot<M>& s = snapshot(in, *state);
                s = Snapshot<M>{in.model, in.phase, in.start_time, in.time, {}};
                return fmi2OK;
            }
            auto s = std::unique_ptr<Snapshot<M>>(new Snapshot<M>{in.model, in.phase, in.start_time, in.time, {}});
            in.snapshots.insert(s.get());
            *state = s.release();
            return fmi2OK;
        });
    }

    static fmi2Status set_fmu_state(void* c, void* state) noexcept {
        return guarded<M, S>(c, S.set_fmu_state, kAnyButFatal, [&](In& in) {
            const Snapshot<M>& s = snapshot(in, state);
            M copy = s.model;
            using std::swap;
            swap(in.model, copy);
            in.phase = s.phase;
            in.initial.reset();
            in.start_time = s.start_time;
            in.time = s.time;
            return fmi2OK;
        });
    }

    static fmi2Status free_fmu_state(void* c, void** state) noexcept {
        return guarded<M, S>(c, S.free_fmu_state, kAnyButFatal, [&](In& in) {
            if (state == nullptr || *state == nullptr) return fmi2OK;
            Snapshot<M>* s = &snapshot(in, *state);
            in.snapshots.erase(s);
            delete s;
            *state = nullptr;
            return fmi2OK;
        });
    }

    static const std::vector<char>& bytes_of(Snapshot<M>& s) {
        if (s.bytes.empty()) s.bytes = serialise(s, S);
        return s.bytes;
    }

    static fmi2Status serialized_fmu_state_size(void* c, void* state, std::size_t* size) noexcept {
        return guarded<M, S>(c, S.serialized_fmu_state_size, kAnyButFatal, [&](In& in) {
            if (size == nullptr) throw Error("size is NULL");
            *size = bytes_of(snapshot(in, state)).size();
            return fmi2OK;
        });
    }

    static fmi2Status serialize_fmu_state(void* c, void* state, char out[], std::size_t size) noexcept {
        return guarded<M, S>(c, S.serialize_fmu_state, kAnyButFatal, [&](In& in) {
            const auto& bytes = bytes_of(snapshot(in, state));
            if (out == nullptr) throw Error("serializedState is NULL");
            if (size < bytes.size())
                throw Error("the buffer has " + std::to_string(size) + " bytes, the state needs " +
                            std::to_string(bytes.size()) + " (" + S.serialized_fmu_state_size + ")");
            std::memcpy(out, bytes.data(), bytes.size());
            return fmi2OK;
        });
    }

    static fmi2Status deserialize_fmu_state(void* c, const char data[], std::size_t size, void** state) noexcept {
        return guarded<M, S>(c, S.deserialize_fmu_state, kAnyButFatal, [&](In& in) {
            if (state == nullptr) throw Error("FMUstate is NULL");
            if (data == nullptr && size > 0) throw Error("serializedState is NULL");
            Snapshot<M>* reuse = *state != nullptr ? &snapshot(in, *state) : nullptr;
            auto s = deserialise(in, data, size);
            if (reuse != nullptr) {
                *reuse = std::move(*s);
                return fmi2OK;
            }
            in.snapshots.insert(s.get());
            *state = s.release();
            return fmi2OK;
        });
    }

    // One communication step from t by h (fmi2DoStep, fmi3DoStep).
    static void step(In& in, double t, double h) {
        if (!std::isfinite(t)) throw Error("currentCommunicationPoint = " + number_text(t) + " is not finite");
        if (!(h > 0.0) || !std::isfinite(h))
            throw Error("communicationStepSize = " + number_text(h) + " must be a finite number > 0");
        if (!follows_last_step(t, in.time, in.start_time))
            throw Error("currentCommunicationPoint = " + number_text(t) + " but the previous step ended at " +
                        number_text(in.time) + " (a step continues where the last one ended)");
        in.undoable([&] { in.model.do_step(t, h); },
                    [&] { return "the step from t = " + number_text(t) + " by h = " + number_text(h); });
        in.time = t + h;
    }
};

}  // namespace fmi::glue
