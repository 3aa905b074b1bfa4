// The FMI 2.0 common and co-simulation functions for a model M, as static members of Fmi2<M>;
// fmi2_entry_points.inc exports them under their C names. Every function with an instance goes
// through guarded(), the one exception boundary. README.md in this folder specifies what each
// function accepts and refuses.
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
Instance<M>* instance_of(fmi2Component c) {
    auto* in = static_cast<Instance<M>*>(c);
    return (in != nullptr && in->tag == Instance<M>::kTag) ? in : nullptr;
}

// Phases in which each group of functions may be called (FMI 2.0, section 4.2.4).
inline constexpr PhaseMask kAnyButFatal =
    mask(Phase::instantiated, Phase::initialization_mode, Phase::step_complete, Phase::terminated, Phase::error);
inline constexpr PhaseMask kGet =
    mask(Phase::initialization_mode, Phase::step_complete, Phase::terminated, Phase::error);
inline constexpr PhaseMask kSet = mask(Phase::instantiated, Phase::initialization_mode, Phase::step_complete);
inline constexpr PhaseMask kStatus = mask(Phase::step_complete, Phase::terminated);

// The variable that vr names, if it has the type of the Get or Set function; else throws.
template <class M>
const Variable<M>& variable_of(fmi2ValueReference vr, Type type) {
    const auto& vars = variables<M>();
    if (vr >= vars.size())
        throw Error("unknown value reference " + std::to_string(vr) + " (this FMU has 0.." +
                    std::to_string(vars.size() - 1) + ")");
    const auto& v = vars[vr];
    if (type_of(v) != type)
        throw Error("value reference " + std::to_string(vr) + " is the " + type_name(type_of(v)) + " " + v.name +
                    ", not " + (type == Type::Integer ? "an " : "a ") + type_name(type));
    return v;
}

// Throws unless a master may set v in phase p: inputs always, fixed parameters until
// fmi2ExitInitializationMode, tunable ones always; outputs and locals never.
template <class M>
void check_settable(const Variable<M>& v, Phase p) {
    switch (v.causality) {
        case Causality::input: return;
        case Causality::parameter:
            if (v.variability == Variability::fixed && p != Phase::instantiated && p != Phase::initialization_mode)
                throw Error(std::string(v.name) +
                            " is a fixed parameter: it can be set only before fmi2ExitInitializationMode"
                            " (the instance is in state " +
                            phase_name(p) + ")");
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
template <class M, class Body>
fmi2Status guarded(fmi2Component c, const char* fn, PhaseMask allowed, Body&& body) noexcept {
    Instance<M>* in = instance_of<M>(c);
    if (in == nullptr) return fmi2Error;  // NULL or not an instance of this FMU: nobody to log to
    try {
        if (in->tracing())
            in->log(fmi2OK, LogCategory::all, std::string(fn) + " (state " + phase_name(in->phase) + ")");
        if (!(mask(in->phase) & allowed)) {
            in->log(fmi2Error, LogCategory::error,
                    std::string(fn) + " is not allowed in state " + phase_name(in->phase) +
                        " (allowed in: " + mask_text(allowed) + "); nothing was changed");
            return fmi2Error;
        }
        // A call that completes returns fmi2OK even when the model logged a warning (status
        // fmi2Warning, category logStatusWarning): strict importers (OMSimulator) end the run on
        // fmi2Warning, and a recoverable condition must not stop a drive cycle.
        return body(*in);
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
                return refuse("GUID " + std::string(guid != nullptr ? guid : "(NULL)") + " does not match " + M::guid +
                              " of this binary: use the modelDescription.xml that came with it");
            std::string resources = resource_dir_from_uri(resource_location);
            auto in = std::make_unique<In>(instance_name, logger, env, logging_on != fmi2False, resources);
            if (resources.empty())
                in->log(
                    fmi2Warning, LogCategory::warning,
                    "fmi2Instantiate: fmuResourceLocation " +
                        std::string(resource_location != nullptr ? "\"" + utf8_excerpt(resource_location, 300) + "\""
                                                                 : "NULL") +
                        " is not a local file URI: the model has no resources directory");
            else
                in->log(fmi2OK, LogCategory::events, "fmi2Instantiate: resources in " + utf8_excerpt(resources, 300));
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
            in.categories = on == fmi2False ? 0u : (n == 0 ? default_categories : bits);
            return fmi2OK;
        });
    }

    static fmi2Status setup_experiment(fmi2Component c, fmi2Boolean /*tolerance_defined*/, fmi2Real /*tolerance*/,
                                       fmi2Real start, fmi2Boolean stop_defined, fmi2Real stop) noexcept {
        return guarded<M>(c, "fmi2SetupExperiment", mask(Phase::instantiated), [&](In& in) {
            if (!std::isfinite(start)) throw Error("startTime = " + number_text(start) + " is not finite");
            if (stop_defined != fmi2False && !(std::isfinite(stop) && stop >= start))
                throw Error("stopTime = " + number_text(stop) +
                            " must be finite and >= startTime = " + number_text(start));
            in.start_time = start;
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
            in.start_time = 0.0;
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
                const auto& v = variable_of<M>(vr[i], type);
                from_initial = from_initial || (init && is_computed(v.causality));
            }
            const M& model = from_initial ? in.initial_model() : in.model;
            const auto& vars = variables<M>();
            if constexpr (std::is_same_v<C, fmi2String>) {
                in.strings.resize(nvr);
                for (std::size_t i = 0; i < nvr; ++i) in.strings[i] = value_of<std::string>(model, vars[vr[i]]);
                for (std::size_t i = 0; i < nvr; ++i) value[i] = in.strings[i].c_str();
            } else {
                for (std::size_t i = 0; i < nvr; ++i) {
                    const auto& v = vars[vr[i]];
                    if constexpr (std::is_same_v<C, fmi2Real>)
                        value[i] = value_of<double>(model, v);
                    else if (type == Type::Integer)
                        value[i] = value_of<int>(model, v);
                    else
                        value[i] = value_of<bool>(model, v) ? fmi2True : fmi2False;
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
                const auto& v = variable_of<M>(vr[i], type);
                check_settable(v, in.phase);
                if constexpr (std::is_same_v<C, fmi2String>) {
                    if (value[i] == nullptr) throw Error(std::string(v.name) + ": the value is a NULL string");
                } else if (type != Type::Boolean) {
                    const double x = static_cast<double>(value[i]);
                    // (the message is built only on failure: this loop runs for every input of every fmi2SetReal)
                    if (!std::isfinite(x) || !in_range(v, x))
                        throw Error(range_error(v, x) + "; kept " + value_text(in.model, v));
                }
            }
            for (std::size_t i = 0; i < nvr; ++i) {
                const auto& v = vars[vr[i]];
                if constexpr (std::is_same_v<C, fmi2String>)
                    set_value(in.model, v, std::string(value[i]));
                else if constexpr (std::is_same_v<C, fmi2Real>)
                    set_value(in.model, v, static_cast<double>(value[i]));
                else if (type == Type::Integer)
                    set_value(in.model, v, static_cast<int>(value[i]));
                else
                    set_value(in.model, v, value[i] != fmi2False);
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
                s = Snapshot<M>{in.model, in.phase, in.start_time, in.time, {}};
                return fmi2OK;
            }
            auto s = std::unique_ptr<Snapshot<M>>(new Snapshot<M>{in.model, in.phase, in.start_time, in.time, {}});
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
            in.start_time = s.start_time;
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

    static fmi2Status serialize_fmu_state(fmi2Component c, fmi2FMUstate state, fmi2Byte out[],
                                          std::size_t size) noexcept {
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
            if (!follows_last_step(t, in.time, in.start_time))
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
                if constexpr (std::is_same_v<V, fmi2Real>)
                    *value = in.time;
                else if constexpr (std::is_same_v<V, fmi2Boolean>)
                    *value = fmi2False;
                return fmi2OK;
            }
            const char* why = (kind == fmi2DoStepStatus || kind == fmi2PendingStatus)
                                  ? "fmi2DoStep computes synchronously and never returns fmi2Pending"
                              : kind == fmi2LastSuccessfulTime
                                  ? "fmi2LastSuccessfulTime is a Real: use fmi2GetRealStatus"
                                  : "fmi2Terminated is a Boolean: use fmi2GetBooleanStatus";
            in.log(fmi2Discard, LogCategory::discard, std::string(fn) + ": " + why);
            return fmi2Discard;
        });
    }
};

}  // namespace fmi::glue
