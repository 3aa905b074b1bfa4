// The FMI 2.0 co-simulation glue, written once for every model (see model.hpp for what a model
// provides). One .cpp per FMU says
//
//     #include "my_model.hpp"
//     #include "fmi2_glue.hpp"
//     IPMSM_FMI2_EXPORT(MyModel)
//
// which defines all FMI 2.0 common and co-simulation functions (extern "C", the only symbols the
// FMU exports). Compiled with IPMSM_FMI2_GENERATOR defined (add_fmu does that for the generator
// executable), the same line defines instead a main() that writes the modelDescription.xml.
//
// Behaviour, beyond the standard's letter:
// - Every call is checked against the state machine of FMI 2.0 (section 4.2.4); a call in the wrong
//   state returns fmi2Error, logs the function and the state, and changes nothing.
// - Exceptions never cross the C boundary: fmi::Error, std::exception and anything else become
//   fmi2Error with the message in the log; std::bad_alloc becomes fmi2Fatal (only
//   fmi2FreeInstance is accepted afterwards).
// - fmi2Error is recoverable, more than the standard requires: refused calls change nothing, and
//   a failing fmi2ExitInitializationMode or fmi2DoStep (an exception, or a non-finite output or
//   local afterwards) restores the model as it was before the call. The instance stays in its
//   state; correct the input or parameter and call again. The "error" state is entered only if
//   that restoring itself fails; fmi2SetFMUstate or fmi2Reset leave it.
// - Set calls validate every value first and then write all of them, or none: unknown value
//   references, wrong types, NULL arrays (nvr > 0), outputs and locals, fixed parameters after
//   initialisation, non-finite Reals, values outside [min, max] are refused.
// - fmi2Instantiate accepts NULL callbacks or a NULL logger (the instance then logs nothing), since
//   the FMU never uses the memory callbacks (canNotUseMemoryManagementFunctions="true"). It
//   returns NULL for a wrong GUID, for fmi2ModelExchange and for an empty instanceName.
// - Log messages are passed to the logger as its format string with every '%' doubled, so that
//   both printf-style loggers and loggers that print the string as is show the message.
// - fmi2DoStep computes synchronously: fmi2CancelStep always returns fmi2Error, the status
//   queries report fmi2Discard for the asynchronous kinds. currentCommunicationPoint must be where
//   the previous step ended (relative tolerance 1e-9); the setupExperiment stop time is not
//   enforced and its tolerance is not used (models have their own tolerance parameters).
// - Outputs in Initialization Mode: FMI 2.0 lists the outputs as InitialUnknowns, which a master
//   may read (fmi2GetReal) before fmi2ExitInitializationMode to propagate them to other FMUs
//   (libcosim, container FMUs do). The glue answers such a Get of an output or local with the
//   values the model will have right after fmi2ExitInitializationMode: it runs
//   exit_initialization() on a copy of the model (logging muted), kept until the next Set. If that
//   fails the Get fails with the reason (fmi2ExitInitializationMode would too).
// - Per fmi2DoStep the glue copy-assigns the model once (to undo a failed step): models keep
//   copy-assignment cheap (large read-only data behind std::shared_ptr<const T>).
// - FMU states are full copies of the model plus the FMI state and time; fmi2FreeInstance frees
//   those still alive. Serialised form: magic, format version, model identifier and GUID, state,
//   time, every variable's type and value, the model's save_state() block, an FNV-1a checksum.
//   Deserialising checks all of that, and refuses a state whose fixed parameters differ from this
//   instance's. A state saved after initialisation can be deserialised into an instance that is
//   not yet initialised: the glue then runs exit_initialization() on the restored parameters (to
//   load the model's data) before load_state().
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <type_traits>
#include <unordered_set>
#include <utility>
#include <vector>

#include "fmi2Functions.h"
#include "fmi2_support.hpp"
#include "model.hpp"
#include "variable.hpp"

namespace fmi {

// The FMI type of a variable: the index of its member pointer in Member<Model>.
enum class Type { Real = 0, Integer = 1, Boolean = 2, String = 3 };

inline const char* type_name(Type t) {
    switch (t) {
        case Type::Real: return "Real";
        case Type::Integer: return "Integer";
        case Type::Boolean: return "Boolean";
        case Type::String: return "String";
    }
    return "?";
}

template <class M>
Type type_of(const Variable<M>& v) {
    return static_cast<Type>(v.member.index());
}

inline const char* causality_name(Causality c) {
    switch (c) {
        case Causality::parameter: return "parameter";
        case Causality::input: return "input";
        case Causality::output: return "output";
        case Causality::local: return "local";
    }
    return "?";
}

inline const char* variability_name(Variability v) {
    switch (v) {
        case Variability::fixed: return "fixed";
        case Variability::tunable: return "tunable";
        case Variability::discrete: return "discrete";
        case Variability::continuous: return "continuous";
    }
    return "?";
}

// "[-100, 100]", "> 0", "> 0 and <= 5", "any finite value"
template <class M>
std::string range_text(const Variable<M>& v) {
    const bool has_min = std::isfinite(v.min), has_max = std::isfinite(v.max);
    if (v.min_exclusive || (has_min != has_max)) {
        std::string s;
        if (has_min) s = (v.min_exclusive ? "> " : ">= ") + number_text(v.min);
        if (has_max) s += (s.empty() ? "<= " : " and <= ") + number_text(v.max);
        return s.empty() ? "any finite value" : s;
    }
    if (!has_min) return "any finite value";
    return "[" + number_text(v.min) + ", " + number_text(v.max) + "]";
}

template <class M>
bool in_range(const Variable<M>& v, double x) {
    return (v.min_exclusive ? x > v.min : x >= v.min) && x <= v.max;
}

namespace glue {

template <class M>
const std::vector<Variable<M>>& variables() {
    static const std::vector<Variable<M>>& table = M::variables();
    return table;
}

// Real variables the model computes (outputs and locals): they must stay finite.
template <class M>
const std::vector<const Variable<M>*>& computed_reals() {
    static const std::vector<const Variable<M>*> list = [] {
        std::vector<const Variable<M>*> l;
        for (const auto& v : variables<M>())
            if (type_of(v) == Type::Real && is_computed(v.causality)) l.push_back(&v);
        return l;
    }();
    return list;
}

inline constexpr unsigned bit(LogCategory c) { return 1u << static_cast<unsigned>(c); }
// loggingOn = true without a list of categories: everything but the call trace.
inline constexpr unsigned default_categories = bit(LogCategory::events) | bit(LogCategory::warning) |
                                               bit(LogCategory::discard) | bit(LogCategory::error) |
                                               bit(LogCategory::fatal);

inline void call_logger(fmi2CallbackLogger logger, fmi2ComponentEnvironment env, const char* instance,
                        fmi2Status status, LogCategory category, const std::string& message) noexcept {
    if (logger == nullptr) return;
    try {
        std::string text;  // the logger treats the message as a printf format
        text.reserve(message.size() + 8);
        for (char ch : message) {
            text += ch;
            if (ch == '%') text += '%';
        }
        logger(env, instance != nullptr ? instance : "", status,
               log_categories[static_cast<unsigned>(category)].name, text.c_str());
    } catch (...) {
    }
}

// An FMU state (fmi2FMUstate): a copy of the model plus where the instance was.
template <class M>
struct Snapshot {
    M model;
    Phase phase;
    double time;
    std::vector<char> bytes;  // the serialised form, made on the first request
};

template <class M>
class Instance {
public:
    // First member: lets the glue recognise its own instances (and not the other FMU's).
    static constexpr std::uint64_t kTag = fnv1a(M::guid) ^ 0x494e5354414e4345ull;
    std::uint64_t tag = kTag;

    const std::string name;
    const fmi2CallbackLogger logger;
    const fmi2ComponentEnvironment environment;
    unsigned categories;  // enabled log categories, bit(LogCategory)
    bool warned = false;  // the model logged a warning during the current call

    Context context;
    M model;
    M backup;  // scratch copy to undo a failing call
    Phase phase = Phase::instantiated;
    double time = 0.0;  // where the next step starts

    std::vector<std::string> strings;  // what fmi2GetString returned last
    std::unique_ptr<M> initial;  // Initialization Mode: the model as exit_initialization() leaves it
    bool quiet = false;          // the model's log messages are dropped (while computing `initial`)
    std::unordered_set<Snapshot<M>*> snapshots;

    Instance(const char* instance_name, fmi2CallbackLogger log, fmi2ComponentEnvironment env,
             bool logging_on, std::string resource_dir)
        : name(instance_name),
          logger(log),
          environment(env),
          categories(logging_on ? default_categories : 0u),
          context(make_context(std::move(resource_dir))),
          model(context),
          backup(model) {}

    ~Instance() {
        for (auto* s : snapshots) delete s;
        *static_cast<volatile std::uint64_t*>(&tag) = 0;  // best effort against a freed component
    }
    Instance(const Instance&) = delete;
    Instance& operator=(const Instance&) = delete;

    void log(fmi2Status status, LogCategory category, const std::string& message) noexcept {
        const bool always = status == fmi2Error || status == fmi2Fatal;
        if (!always && !(categories & (bit(category) | bit(LogCategory::all)))) return;
        call_logger(logger, environment, name.c_str(), status, category, message);
    }
    bool tracing() const { return (categories & bit(LogCategory::all)) != 0; }

    const Variable<M>& lookup(fmi2ValueReference vr, Type type) const {
        const auto& vars = variables<M>();
        if (vr >= vars.size())
            throw Error("unknown value reference " + std::to_string(vr) + " (this FMU has 0.." +
                        std::to_string(vars.size() - 1) + ")");
        const auto& v = vars[vr];
        if (type_of(v) != type)
            throw Error("value reference " + std::to_string(vr) + " is the " + type_name(type_of(v)) + " " +
                        v.name + ", not " + (type == Type::Integer ? "an " : "a ") + type_name(type));
        return v;
    }

    void check_settable(const Variable<M>& v) const {
        switch (v.causality) {
            case Causality::input: return;
            case Causality::parameter:
                if (v.variability == Variability::fixed && phase != Phase::instantiated &&
                    phase != Phase::initialization_mode)
                    throw Error(std::string(v.name) +
                                " is a fixed parameter: it can be set only before fmi2ExitInitializationMode"
                                " (the instance is in state " + phase_name(phase) + ")");
                return;
            case Causality::output:
            case Causality::local:
                throw Error(std::string(v.name) + " is " + (v.causality == Causality::output ? "an " : "a ") +
                            causality_name(v.causality) + ": only inputs and parameters can be set");
        }
    }

    static double value_of(const M& m, const Variable<M>* v) { return m.*std::get<double M::*>(v->member); }
    // The first computed Real of m that is not finite, or nullptr.
    static const Variable<M>* first_non_finite(const M& m) {
        for (const Variable<M>* v : computed_reals<M>())
            if (!std::isfinite(value_of(m, v))) return v;
        return nullptr;
    }

    // Runs f (a model call) so that, if it throws or leaves a computed Real non-finite, the model
    // is as before. what() describes the call for the log; it is called only on failure (a step's
    // description costs as much as the glue's whole per-step work otherwise).
    template <class F, class W>
    void undoable(F&& f, W&& what) {
        backup = model;
        try {
            f();
            if (const Variable<M>* v = first_non_finite(model))
                throw Error(std::string("the model computed ") + v->name + " = " + number_text(value_of(model, v)) +
                            ", not a finite number");
        } catch (const std::bad_alloc&) {
            restore();
            throw;
        } catch (const std::exception& e) {
            restore();
            throw Error(undone(e.what(), what()));
        } catch (...) {
            restore();
            throw Error(undone("unknown exception (not a std::exception)", what()));
        }
    }

    // Initialization Mode: the model as fmi2ExitInitializationMode will leave it, for the Get of an
    // output or local (see the header). Computed on a copy, with the model's logging muted; kept
    // until a Set, fmi2SetFMUstate, fmi2Reset or fmi2ExitInitializationMode drops it.
    const M& initial_model() {
        if (initial) return *initial;
        auto m = std::make_unique<M>(model);
        struct Mute {
            bool& q;
            explicit Mute(bool& flag) : q(flag) { q = true; }
            ~Mute() { q = false; }
        } mute(quiet);
        const char* why = "the outputs cannot be computed in Initialization Mode with the values set so far: ";
        try {
            m->exit_initialization();
        } catch (const std::bad_alloc&) {
            throw;
        } catch (const std::exception& e) {
            throw Error(why + std::string(e.what()) + " (fmi2ExitInitializationMode would fail the same way)");
        } catch (...) {
            throw Error(why + std::string("unknown exception (not a std::exception)"));
        }
        if (const Variable<M>* v = first_non_finite(*m))
            throw Error(why + std::string("the model computes ") + v->name + " = " + number_text(value_of(*m, v)));
        initial = std::move(m);
        return *initial;
    }

private:
    Context make_context(std::string resource_dir) {
        Context c;
        c.instance_name = name;
        c.resource_dir = std::move(resource_dir);
        c.log_info = [this](const std::string& m) {
            if (!quiet) log(fmi2OK, LogCategory::events, m);
        };
        c.log_warning = [this](const std::string& m) {
            if (quiet) return;
            warned = true;
            log(fmi2Warning, LogCategory::warning, m);
        };
        return c;
    }

    std::string undone(const std::string& cause, const std::string& what) const {
        if (phase == Phase::error) return cause + " [" + what + "; the model could not be restored: state error]";
        return cause + " [" + what + " was undone: the instance is as before the call and can be used again]";
    }

    void restore() noexcept {
        try {
            using std::swap;
            swap(model, backup);
        } catch (...) {
            phase = Phase::error;
        }
    }
};

// The value of an enum argument from C, read without assuming it is one of the enumerators.
template <class E>
int enum_value(const E& e) {
    std::underlying_type_t<E> v;
    std::memcpy(&v, &e, sizeof v);
    return static_cast<int>(v);
}

template <class M>
Instance<M>* instance_of(fmi2Component c) {
    auto* in = static_cast<Instance<M>*>(c);
    return (in != nullptr && in->tag == Instance<M>::kTag) ? in : nullptr;
}

// Phases in which each group of functions may be called (FMI 2.0, section 4.2.4).
inline constexpr PhaseMask kAnyButFatal = mask(Phase::instantiated, Phase::initialization_mode,
                                               Phase::step_complete, Phase::terminated, Phase::error);
inline constexpr PhaseMask kGet =
    mask(Phase::initialization_mode, Phase::step_complete, Phase::terminated, Phase::error);
inline constexpr PhaseMask kSet = mask(Phase::instantiated, Phase::initialization_mode, Phase::step_complete);
inline constexpr PhaseMask kStatus = mask(Phase::step_complete, Phase::terminated);

// The one exception boundary: every function with an instance goes through here.
template <class M, class Body>
fmi2Status guarded(fmi2Component c, const char* fn, PhaseMask allowed, Body&& body) noexcept {
    Instance<M>* in = instance_of<M>(c);
    if (in == nullptr) return fmi2Error;  // NULL or not an instance of this FMU: nobody to log to
    try {
        if (in->tracing()) in->log(fmi2OK, LogCategory::all, std::string(fn) + " (state " + phase_name(in->phase) + ")");
        if (!(mask(in->phase) & allowed)) {
            in->log(fmi2Error, LogCategory::error,
                    std::string(fn) + " is not allowed in state " + phase_name(in->phase) +
                        " (allowed in: " + mask_text(allowed) + "); nothing was changed");
            return fmi2Error;
        }
        in->warned = false;
        const fmi2Status s = body(*in);
        return (s == fmi2OK && in->warned) ? fmi2Warning : s;
    } catch (const std::bad_alloc&) {
        in->phase = Phase::fatal;
        call_logger(in->logger, in->environment, in->name.c_str(), fmi2Fatal, LogCategory::fatal,
                    std::string(fn) + ": out of memory; only fmi2FreeInstance is possible now");
        return fmi2Fatal;
    } catch (const std::exception& e) {
        in->log(fmi2Error, LogCategory::error, std::string(fn) + ": " + e.what());
        return fmi2Error;
    } catch (...) {
        in->log(fmi2Error, LogCategory::error, std::string(fn) + ": unknown exception (not a std::exception)");
        return fmi2Error;
    }
}

template <class M>
std::string value_text(const M& m, const Variable<M>& v) {
    return std::visit(
        [&](auto p) -> std::string {
            using T = std::decay_t<decltype(m.*p)>;
            if constexpr (std::is_same_v<T, double>) return number_text(m.*p);
            else if constexpr (std::is_same_v<T, int>) return std::to_string(m.*p);
            else if constexpr (std::is_same_v<T, bool>) return m.*p ? "true" : "false";
            else return "\"" + m.*p + "\"";
        },
        v.member);
}

// --- FMU-state serialisation ---
inline constexpr char kStateMagic[8] = {'I', 'P', 'M', 'S', 'M', 'F', 'S', 'T'};
inline constexpr std::uint32_t kStateFormat = 1;

template <class M>
std::vector<char> serialise(const Snapshot<M>& s) {
    std::vector<char> out(kStateMagic, kStateMagic + sizeof kStateMagic);
    StateWriter w(out);
    w.put<std::uint32_t>(kStateFormat);
    w.put_string(M::model_identifier);
    w.put_string(M::guid);
    w.put<std::uint8_t>(static_cast<std::uint8_t>(s.phase));
    w.put<double>(s.time);
    const auto& vars = variables<M>();
    w.put<std::uint64_t>(vars.size());
    for (const auto& v : vars) {
        w.put<std::uint8_t>(static_cast<std::uint8_t>(v.member.index()));
        std::visit(
            [&](auto p) {
                using T = std::decay_t<decltype(s.model.*p)>;
                if constexpr (std::is_same_v<T, std::string>) w.put_string(s.model.*p);
                else if constexpr (std::is_same_v<T, bool>) w.put<std::uint8_t>(s.model.*p ? 1 : 0);
                else if constexpr (std::is_same_v<T, int>) w.put<std::int32_t>(s.model.*p);
                else w.put<double>(s.model.*p);
            },
            v.member);
    }
    std::vector<char> block;
    StateWriter bw(block);
    s.model.save_state(bw);
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
        throw Error(std::string(what) + " belongs to " + id + " " + guid + ", not to " + M::model_identifier +
                    " " + M::guid);
    const auto phase_value = r.get<std::uint8_t>();
    if (phase_value < static_cast<std::uint8_t>(Phase::instantiated) ||
        phase_value > static_cast<std::uint8_t>(Phase::terminated))
        throw Error(std::string(what) + " has an invalid instance state (" + std::to_string(phase_value) + ")");
    const auto phase = static_cast<Phase>(phase_value);
    const double time = r.get<double>();
    if (!std::isfinite(time)) throw Error(std::string(what) + " has a non-finite time");
    const auto& vars = variables<M>();
    if (const auto n = r.get<std::uint64_t>(); n != vars.size())
        throw Error(std::string(what) + " has " + std::to_string(n) + " variables; this FMU has " +
                    std::to_string(vars.size()));

    M m = in.model;
    std::string mismatch;
    for (const auto& v : vars) {
        if (r.get<std::uint8_t>() != v.member.index())
            throw Error(std::string(what) + ": variable " + v.name + " has another type");
        std::visit(
            [&](auto p) {
                using T = std::decay_t<decltype(m.*p)>;
                T x{};
                if constexpr (std::is_same_v<T, std::string>) x = r.get_string();
                else if constexpr (std::is_same_v<T, bool>) x = r.get<std::uint8_t>() != 0;
                else if constexpr (std::is_same_v<T, int>) x = r.get<std::int32_t>();
                else {
                    x = r.get<double>();
                    if (!std::isfinite(x))
                        throw Error(std::string(what) + ": variable " + v.name + " is not finite");
                }
                m.*p = x;
            },
            v.member);
        if (v.causality == Causality::parameter && v.variability == Variability::fixed) {
            const std::string there = value_text(m, v), here = value_text(in.model, v);
            if (there != here) mismatch += std::string(mismatch.empty() ? "" : ", ") + v.name + " = " + there +
                                           " there, " + here + " here";
        }
    }
    if (!mismatch.empty())
        throw Error(std::string(what) + " was saved with other fixed parameters than this instance has (" +
                    mismatch + "); set the same parameters before fmi2DeSerializeFMUstate");

    const bool saved_initialised = phase == Phase::step_complete || phase == Phase::terminated;
    const bool here_initialised = in.phase == Phase::step_complete || in.phase == Phase::terminated;
    if (saved_initialised && !here_initialised) {
        // The model's data (loaded by exit_initialization) is not in the state: load it with the
        // saved parameters, then put the saved values back.
        M initialised = m;
        initialised.exit_initialization();
        for (const auto& v : vars) std::visit([&](auto p) { initialised.*p = m.*p; }, v.member);
        m = std::move(initialised);
    }

    const std::string block = r.get_string();
    StateReader br(block.data(), block.size());
    m.load_state(br);
    if (!br.at_end()) throw Error(std::string(what) + ": the model did not read all of its state block");
    if (!r.at_end()) throw Error(std::string(what) + " has trailing bytes");
    return std::unique_ptr<Snapshot<M>>(new Snapshot<M>{std::move(m), phase, time, {}});
}

// --- the FMI functions, for model M ---
template <class M>
struct Fmi2 {
    using In = Instance<M>;

    static fmi2Component instantiate(fmi2String instance_name, fmi2Type type, fmi2String guid,
                                     fmi2String resource_location, const fmi2CallbackFunctions* functions,
                                     fmi2Boolean /*visible*/, fmi2Boolean logging_on) noexcept {
        const fmi2CallbackLogger logger = functions != nullptr ? functions->logger : nullptr;
        const fmi2ComponentEnvironment env = functions != nullptr ? functions->componentEnvironment : nullptr;
        auto refuse = [&](const std::string& why) -> fmi2Component {
            call_logger(logger, env, instance_name, fmi2Error, LogCategory::error, "fmi2Instantiate: " + why);
            return nullptr;
        };
        try {
            if (instance_name == nullptr || instance_name[0] == '\0')
                return refuse("instanceName must be a non-empty string");
            if (enum_value(type) != fmi2CoSimulation)
                return refuse(std::string(M::model_identifier) +
                              " is a co-simulation FMU: fmuType must be fmi2CoSimulation");
            if (guid == nullptr || std::strcmp(guid, M::guid) != 0)
                return refuse("GUID " + std::string(guid != nullptr ? guid : "(NULL)") + " does not match " +
                              M::guid + " of this binary: use the modelDescription.xml that came with it");
            std::string resources = resource_dir_from_uri(resource_location);
            auto in = std::make_unique<In>(instance_name, logger, env, logging_on != fmi2False, resources);
            if (resources.empty())
                in->log(fmi2Warning, LogCategory::warning,
                        "fmi2Instantiate: fmuResourceLocation " +
                            std::string(resource_location != nullptr ? "\"" + std::string(resource_location) + "\"" : "NULL") +
                            " is not a local file URI: the model has no resources directory");
            else
                in->log(fmi2OK, LogCategory::events, "fmi2Instantiate: resources in " + resources);
            return in.release();
        } catch (const std::exception& e) {
            return refuse(e.what());
        } catch (...) {
            return refuse("unknown exception (not a std::exception)");
        }
    }

    static void free_instance(fmi2Component c) noexcept { delete instance_of<M>(c); }

    static fmi2Status set_debug_logging(fmi2Component c, fmi2Boolean on, std::size_t n,
                                        const fmi2String categories[]) noexcept {
        return guarded<M>(c, "fmi2SetDebugLogging", kAnyButFatal, [&](In& in) {
            if (n > 0 && categories == nullptr) throw Error("categories is NULL with nCategories > 0");
            unsigned bits = 0;
            for (std::size_t i = 0; i < n; ++i) {
                const char* name = categories[i];
                unsigned k = 0;
                while (k < log_categories.size() && (name == nullptr || std::strcmp(name, log_categories[k].name) != 0)) ++k;
                if (k == log_categories.size()) {
                    std::string known;
                    for (const auto& lc : log_categories) known += std::string(known.empty() ? "" : ", ") + lc.name;
                    throw Error("unknown log category \"" + std::string(name != nullptr ? name : "(NULL)") +
                                "\" (known: " + known + ")");
                }
                bits |= 1u << k;
            }
            in.categories = on == fmi2False ? 0u : (n == 0 ? default_categories : bits);
            return fmi2OK;
        });
    }

    static fmi2Status setup_experiment(fmi2Component c, fmi2Boolean /*tolerance_defined*/, fmi2Real /*tolerance*/,
                                       fmi2Real start, fmi2Boolean stop_defined, fmi2Real stop) noexcept {
        return guarded<M>(c, "fmi2SetupExperiment", mask(Phase::instantiated), [&](In& in) {
            if (!std::isfinite(start)) throw Error("startTime = " + number_text(start) + " is not finite");
            if (stop_defined != fmi2False && !(std::isfinite(stop) && stop >= start))
                throw Error("stopTime = " + number_text(stop) + " must be finite and >= startTime = " + number_text(start));
            in.time = start;
            return fmi2OK;
        });
    }

    static fmi2Status enter_initialization_mode(fmi2Component c) noexcept {
        return guarded<M>(c, "fmi2EnterInitializationMode", mask(Phase::instantiated), [&](In& in) {
            in.phase = Phase::initialization_mode;
            return fmi2OK;
        });
    }

    static fmi2Status exit_initialization_mode(fmi2Component c) noexcept {
        return guarded<M>(c, "fmi2ExitInitializationMode", mask(Phase::initialization_mode), [&](In& in) {
            in.undoable([&] { in.model.exit_initialization(); }, [] { return std::string("initialisation"); });
            in.initial.reset();
            in.phase = Phase::step_complete;
            return fmi2OK;
        });
    }

    static fmi2Status terminate(fmi2Component c) noexcept {
        return guarded<M>(c, "fmi2Terminate", mask(Phase::step_complete), [&](In& in) {
            in.phase = Phase::terminated;
            return fmi2OK;
        });
    }

    static fmi2Status reset(fmi2Component c) noexcept {
        return guarded<M>(c, "fmi2Reset", kAnyButFatal, [&](In& in) {
            M fresh(in.context);
            using std::swap;
            swap(in.model, fresh);
            in.initial.reset();
            in.phase = Phase::instantiated;
            in.time = 0.0;
            return fmi2OK;
        });
    }

    // --- values ---
    template <class C>
    static fmi2Status get(fmi2Component c, const char* fn, Type type, const fmi2ValueReference vr[], std::size_t nvr,
                          C value[]) noexcept {
        return guarded<M>(c, fn, kGet, [&](In& in) {
            if (nvr == 0) return fmi2OK;
            if (vr == nullptr || value == nullptr) throw Error("vr[] or value[] is NULL with nvr > 0");
            // In Initialization Mode an output or local comes from initial_model().
            const bool init = in.phase == Phase::initialization_mode;
            bool from_initial = false;
            for (std::size_t i = 0; i < nvr; ++i) {
                const auto& v = in.lookup(vr[i], type);
                from_initial = from_initial || (init && is_computed(v.causality));
            }
            const M& model = from_initial ? in.initial_model() : in.model;
            const auto& vars = variables<M>();
            if constexpr (std::is_same_v<C, fmi2String>) {
                in.strings.resize(nvr);
                for (std::size_t i = 0; i < nvr; ++i) in.strings[i] = model.*std::get<std::string M::*>(vars[vr[i]].member);
                for (std::size_t i = 0; i < nvr; ++i) value[i] = in.strings[i].c_str();
            } else {
                for (std::size_t i = 0; i < nvr; ++i) {
                    const auto& m = vars[vr[i]].member;
                    if constexpr (std::is_same_v<C, fmi2Real>) value[i] = model.*std::get<double M::*>(m);
                    else if (type == Type::Integer) value[i] = model.*std::get<int M::*>(m);
                    else value[i] = model.*std::get<bool M::*>(m) ? fmi2True : fmi2False;
                }
            }
            return fmi2OK;
        });
    }

    template <class C>
    static fmi2Status set(fmi2Component c, const char* fn, Type type, const fmi2ValueReference vr[], std::size_t nvr,
                          const C value[]) noexcept {
        return guarded<M>(c, fn, kSet, [&](In& in) {
            if (nvr == 0) return fmi2OK;
            if (vr == nullptr || value == nullptr) throw Error("vr[] or value[] is NULL with nvr > 0");
            const auto& vars = variables<M>();
            for (std::size_t i = 0; i < nvr; ++i) {  // validate everything, then write
                const auto& v = in.lookup(vr[i], type);
                in.check_settable(v);
                if constexpr (std::is_same_v<C, fmi2String>) {
                    if (value[i] == nullptr) throw Error(std::string(v.name) + ": the value is a NULL string");
                } else if (type != Type::Boolean) {
                    const double x = static_cast<double>(value[i]);
                    if (!std::isfinite(x))
                        throw Error(std::string(v.name) + " = " + number_text(x) + " is not a finite number; kept " +
                                    value_text(in.model, v));
                    if (!in_range(v, x)) {
                        // built only for the message: this loop runs for every input of every fmi2SetReal
                        const std::string unit = (v.unit != nullptr && v.unit[0] != '\0') ? std::string(" ") + v.unit : "";
                        throw Error(std::string(v.name) + " = " + number_text(x) + unit + " is out of range: it must be " +
                                    range_text(v) + "; kept " + value_text(in.model, v));
                    }
                }
            }
            for (std::size_t i = 0; i < nvr; ++i) {
                const auto& m = vars[vr[i]].member;
                if constexpr (std::is_same_v<C, fmi2String>) in.model.*std::get<std::string M::*>(m) = value[i];
                else if constexpr (std::is_same_v<C, fmi2Real>) in.model.*std::get<double M::*>(m) = value[i];
                else if (type == Type::Integer) in.model.*std::get<int M::*>(m) = value[i];
                else in.model.*std::get<bool M::*>(m) = value[i] != fmi2False;
            }
            in.initial.reset();
            return fmi2OK;
        });
    }

    // --- FMU states ---
    static Snapshot<M>& snapshot(In& in, fmi2FMUstate s) {
        auto* p = static_cast<Snapshot<M>*>(s);
        if (s == nullptr || in.snapshots.count(p) == 0)
            throw Error("the FMUstate is not one of this instance's (or was freed)");
        return *p;
    }

    static fmi2Status get_fmu_state(fmi2Component c, fmi2FMUstate* state) noexcept {
        return guarded<M>(c, "fmi2GetFMUstate", kAnyButFatal & ~mask(Phase::error), [&](In& in) {
            if (state == nullptr) throw Error("FMUstate is NULL");
            if (*state != nullptr) {  // reuse a state returned earlier
                Snapshot<M>& s = snapshot(in, *state);
                s = Snapshot<M>{in.model, in.phase, in.time, {}};
                return fmi2OK;
            }
            auto s = std::unique_ptr<Snapshot<M>>(new Snapshot<M>{in.model, in.phase, in.time, {}});
            in.snapshots.insert(s.get());
            *state = s.release();
            return fmi2OK;
        });
    }

    static fmi2Status set_fmu_state(fmi2Component c, fmi2FMUstate state) noexcept {
        return guarded<M>(c, "fmi2SetFMUstate", kAnyButFatal, [&](In& in) {
            const Snapshot<M>& s = snapshot(in, state);
            M copy = s.model;
            using std::swap;
            swap(in.model, copy);
            in.phase = s.phase;
            in.initial.reset();
            in.time = s.time;
            return fmi2OK;
        });
    }

    static fmi2Status free_fmu_state(fmi2Component c, fmi2FMUstate* state) noexcept {
        return guarded<M>(c, "fmi2FreeFMUstate", kAnyButFatal, [&](In& in) {
            if (state == nullptr || *state == nullptr) return fmi2OK;
            Snapshot<M>* s = &snapshot(in, *state);
            in.snapshots.erase(s);
            delete s;
            *state = nullptr;
            return fmi2OK;
        });
    }

    static const std::vector<char>& bytes_of(Snapshot<M>& s) {
        if (s.bytes.empty()) s.bytes = serialise(s);
        return s.bytes;
    }

    static fmi2Status serialized_fmu_state_size(fmi2Component c, fmi2FMUstate state, std::size_t* size) noexcept {
        return guarded<M>(c, "fmi2SerializedFMUstateSize", kAnyButFatal, [&](In& in) {
            if (size == nullptr) throw Error("size is NULL");
            *size = bytes_of(snapshot(in, state)).size();
            return fmi2OK;
        });
    }

    static fmi2Status serialize_fmu_state(fmi2Component c, fmi2FMUstate state, fmi2Byte out[], std::size_t size) noexcept {
        return guarded<M>(c, "fmi2SerializeFMUstate", kAnyButFatal, [&](In& in) {
            const auto& bytes = bytes_of(snapshot(in, state));
            if (out == nullptr) throw Error("serializedState is NULL");
            if (size < bytes.size())
                throw Error("the buffer has " + std::to_string(size) + " bytes, the state needs " +
                            std::to_string(bytes.size()) + " (fmi2SerializedFMUstateSize)");
            std::memcpy(out, bytes.data(), bytes.size());
            return fmi2OK;
        });
    }

    static fmi2Status deserialize_fmu_state(fmi2Component c, const fmi2Byte data[], std::size_t size,
                                            fmi2FMUstate* state) noexcept {
        return guarded<M>(c, "fmi2DeSerializeFMUstate", kAnyButFatal, [&](In& in) {
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

    static fmi2Status get_directional_derivative(fmi2Component c, const fmi2ValueReference*, std::size_t,
                                                 const fmi2ValueReference*, std::size_t, const fmi2Real*,
                                                 fmi2Real*) noexcept {
        return guarded<M>(c, "fmi2GetDirectionalDerivative", kGet, [&](In&) -> fmi2Status {
            throw Error("not provided by this FMU (providesDirectionalDerivative=\"false\")");
        });
    }

    // --- co-simulation ---
    static fmi2Status set_real_input_derivatives(fmi2Component c, const fmi2ValueReference*, std::size_t,
                                                 const fmi2Integer*, const fmi2Real*) noexcept {
        return guarded<M>(c, "fmi2SetRealInputDerivatives", kSet, [&](In&) -> fmi2Status {
            throw Error("this FMU cannot interpolate inputs (canInterpolateInputs=\"false\")");
        });
    }

    static fmi2Status get_real_output_derivatives(fmi2Component c, const fmi2ValueReference*, std::size_t,
                                                  const fmi2Integer*, fmi2Real*) noexcept {
        return guarded<M>(c, "fmi2GetRealOutputDerivatives",
                          mask(Phase::step_complete, Phase::terminated, Phase::error), [&](In&) -> fmi2Status {
                              throw Error("this FMU provides no output derivatives (maxOutputDerivativeOrder=\"0\")");
                          });
    }

    static fmi2Status do_step(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean /*no_set_state_prior*/) noexcept {
        return guarded<M>(c, "fmi2DoStep", mask(Phase::step_complete), [&](In& in) {
            if (!std::isfinite(t)) throw Error("currentCommunicationPoint = " + number_text(t) + " is not finite");
            if (!(h > 0.0) || !std::isfinite(h))
                throw Error("communicationStepSize = " + number_text(h) + " must be a finite number > 0");
            if (std::abs(t - in.time) > 1e-9 * std::max(1.0, std::abs(in.time)))
                throw Error("currentCommunicationPoint = " + number_text(t) + " but the previous step ended at " +
                            number_text(in.time) + " (a step continues where the last one ended)");
            in.undoable([&] { in.model.do_step(t, h); },
                        [&] { return "the step from t = " + number_text(t) + " by h = " + number_text(h); });
            in.time = t + h;
            return fmi2OK;
        });
    }

    static fmi2Status cancel_step(fmi2Component c) noexcept {
        return guarded<M>(c, "fmi2CancelStep", kAnyButFatal, [&](In&) -> fmi2Status {
            throw Error("fmi2DoStep computes synchronously and never returns fmi2Pending: there is no step to cancel");
        });
    }

    // The status queries. `answers` is the one kind this function reports (-1: none): a Real
    // fmi2LastSuccessfulTime, a Boolean fmi2Terminated (always false: the FMU never asks to stop).
    template <class V>
    static fmi2Status status(fmi2Component c, const char* fn, fmi2StatusKind s, V* value, int answers) noexcept {
        const int kind = enum_value(s);
        return guarded<M>(c, fn, kStatus, [&](In& in) {
            if (value == nullptr) throw Error("value is NULL");
            if (kind != fmi2DoStepStatus && kind != fmi2PendingStatus && kind != fmi2LastSuccessfulTime &&
                kind != fmi2Terminated)
                throw Error("unknown status kind " + std::to_string(kind));
            if (kind == answers) {
                if constexpr (std::is_same_v<V, fmi2Real>) *value = in.time;
                else if constexpr (std::is_same_v<V, fmi2Boolean>) *value = fmi2False;
                return fmi2OK;
            }
            const char* why = (kind == fmi2DoStepStatus || kind == fmi2PendingStatus)
                                  ? "fmi2DoStep computes synchronously and never returns fmi2Pending"
                              : kind == fmi2LastSuccessfulTime ? "fmi2LastSuccessfulTime is a Real: use fmi2GetRealStatus"
                                                               : "fmi2Terminated is a Boolean: use fmi2GetBooleanStatus";
            in.log(fmi2Discard, LogCategory::discard, std::string(fn) + ": " + why);
            return fmi2Discard;
        });
    }
};

}  // namespace glue
}  // namespace fmi

#ifdef IPMSM_FMI2_GENERATOR
#include "model_description.hpp"
#define IPMSM_FMI2_EXPORT(Model) IPMSM_FMI2_MODEL_DESCRIPTION_MAIN(Model)
#else
#define IPMSM_FMI2_EXPORT(Model)                                                                                       \
    extern "C" {                                                                                                       \
    const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }                                               \
    const char* fmi2GetVersion(void) { return fmi2Version; }                                                           \
    fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {                \
        return ::fmi::glue::Fmi2<Model>::set_debug_logging(c, on, n, cat);                                             \
    }                                                                                                                  \
    fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,               \
                                  const fmi2CallbackFunctions* functions, fmi2Boolean visible, fmi2Boolean log) {      \
        return ::fmi::glue::Fmi2<Model>::instantiate(name, type, guid, resources, functions, visible, log);            \
    }                                                                                                                  \
    void fmi2FreeInstance(fmi2Component c) { ::fmi::glue::Fmi2<Model>::free_instance(c); }                             \
    fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,             \
                                   fmi2Boolean stop_defined, fmi2Real stop) {                                          \
        return ::fmi::glue::Fmi2<Model>::setup_experiment(c, tol_defined, tol, start, stop_defined, stop);             \
    }                                                                                                                  \
    fmi2Status fmi2EnterInitializationMode(fmi2Component c) {                                                          \
        return ::fmi::glue::Fmi2<Model>::enter_initialization_mode(c);                                                 \
    }                                                                                                                  \
    fmi2Status fmi2ExitInitializationMode(fmi2Component c) {                                                           \
        return ::fmi::glue::Fmi2<Model>::exit_initialization_mode(c);                                                  \
    }                                                                                                                  \
    fmi2Status fmi2Terminate(fmi2Component c) { return ::fmi::glue::Fmi2<Model>::terminate(c); }                       \
    fmi2Status fmi2Reset(fmi2Component c) { return ::fmi::glue::Fmi2<Model>::reset(c); }                               \
    fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {                   \
        return ::fmi::glue::Fmi2<Model>::get(c, "fmi2GetReal", ::fmi::Type::Real, vr, n, v);                           \
    }                                                                                                                  \
    fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {             \
        return ::fmi::glue::Fmi2<Model>::get(c, "fmi2GetInteger", ::fmi::Type::Integer, vr, n, v);                     \
    }                                                                                                                  \
    fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {             \
        return ::fmi::glue::Fmi2<Model>::get(c, "fmi2GetBoolean", ::fmi::Type::Boolean, vr, n, v);                     \
    }                                                                                                                  \
    fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {               \
        return ::fmi::glue::Fmi2<Model>::get(c, "fmi2GetString", ::fmi::Type::String, vr, n, v);                       \
    }                                                                                                                  \
    fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {             \
        return ::fmi::glue::Fmi2<Model>::set(c, "fmi2SetReal", ::fmi::Type::Real, vr, n, v);                           \
    }                                                                                                                  \
    fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {       \
        return ::fmi::glue::Fmi2<Model>::set(c, "fmi2SetInteger", ::fmi::Type::Integer, vr, n, v);                     \
    }                                                                                                                  \
    fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {       \
        return ::fmi::glue::Fmi2<Model>::set(c, "fmi2SetBoolean", ::fmi::Type::Boolean, vr, n, v);                     \
    }                                                                                                                  \
    fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {         \
        return ::fmi::glue::Fmi2<Model>::set(c, "fmi2SetString", ::fmi::Type::String, vr, n, v);                       \
    }                                                                                                                  \
    fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* s) {                                                     \
        return ::fmi::glue::Fmi2<Model>::get_fmu_state(c, s);                                                          \
    }                                                                                                                  \
    fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {                                                      \
        return ::fmi::glue::Fmi2<Model>::set_fmu_state(c, s);                                                          \
    }                                                                                                                  \
    fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* s) {                                                    \
        return ::fmi::glue::Fmi2<Model>::free_fmu_state(c, s);                                                         \
    }                                                                                                                  \
    fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t* size) {                             \
        return ::fmi::glue::Fmi2<Model>::serialized_fmu_state_size(c, s, size);                                        \
    }                                                                                                                  \
    fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte out[], size_t size) {                   \
        return ::fmi::glue::Fmi2<Model>::serialize_fmu_state(c, s, out, size);                                         \
    }                                                                                                                  \
    fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte in[], size_t size, fmi2FMUstate* s) {           \
        return ::fmi::glue::Fmi2<Model>::deserialize_fmu_state(c, in, size, s);                                        \
    }                                                                                                                  \
    fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,                  \
                                            const fmi2ValueReference k[], size_t nk, const fmi2Real dk[],              \
                                            fmi2Real du[]) {                                                           \
        return ::fmi::glue::Fmi2<Model>::get_directional_derivative(c, u, nu, k, nk, dk, du);                          \
    }                                                                                                                  \
    fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,                   \
                                           const fmi2Integer order[], const fmi2Real v[]) {                            \
        return ::fmi::glue::Fmi2<Model>::set_real_input_derivatives(c, vr, n, order, v);                               \
    }                                                                                                                  \
    fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,                  \
                                            const fmi2Integer order[], fmi2Real v[]) {                                 \
        return ::fmi::glue::Fmi2<Model>::get_real_output_derivatives(c, vr, n, order, v);                              \
    }                                                                                                                  \
    fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {                             \
        return ::fmi::glue::Fmi2<Model>::do_step(c, t, h, no_prior);                                                   \
    }                                                                                                                  \
    fmi2Status fmi2CancelStep(fmi2Component c) { return ::fmi::glue::Fmi2<Model>::cancel_step(c); }                    \
    fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status* v) {                                 \
        return ::fmi::glue::Fmi2<Model>::status(c, "fmi2GetStatus", s, v, -1);                                         \
    }                                                                                                                  \
    fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* v) {                               \
        return ::fmi::glue::Fmi2<Model>::status(c, "fmi2GetRealStatus", s, v, fmi2LastSuccessfulTime);                 \
    }                                                                                                                  \
    fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer* v) {                         \
        return ::fmi::glue::Fmi2<Model>::status(c, "fmi2GetIntegerStatus", s, v, -1);                                  \
    }                                                                                                                  \
    fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* v) {                         \
        return ::fmi::glue::Fmi2<Model>::status(c, "fmi2GetBooleanStatus", s, v, fmi2Terminated);                      \
    }                                                                                                                  \
    fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String* v) {                           \
        return ::fmi::glue::Fmi2<Model>::status(c, "fmi2GetStringStatus", s, v, -1);                                   \
    }                                                                                                                  \
    }
#endif
