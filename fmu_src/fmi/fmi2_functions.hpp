// The FMI 2.0 common and co-simulation functions for a model M, as static members of Fmi2<M>:
// those FMI 3.0 shares (glue_functions.hpp) and FMI 2.0's own; fmi2_entry_points.inc exports them
// under their C names. README.md in this folder specifies what each function accepts and refuses.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <type_traits>

#include "fmi2Functions.h"
#include "glue_functions.hpp"

namespace fmi::glue {

template <class M>
struct Fmi2 : Functions<M, fmi2_standard> {
    using In = Instance<M>;
    using Functions<M, fmi2_standard>::create;
    using Functions<M, fmi2_standard>::set_experiment;
    using Functions<M, fmi2_standard>::step;

    static fmi2Component instantiate(fmi2String instance_name, fmi2Type type, fmi2String guid,
                                     fmi2String resource_location, const fmi2CallbackFunctions* functions,
                                     fmi2Boolean /*visible*/, fmi2Boolean logging_on) noexcept {
        const Logger logger{functions != nullptr ? functions->logger : nullptr, nullptr,
                            functions != nullptr ? functions->componentEnvironment : nullptr};
        if (enum_value(type) != fmi2CoSimulation) {
            call_logger(logger, instance_name, fmi2Error, LogCategory::error,
                        "fmi2Instantiate: " + std::string(M::model_identifier) +
                            " is a co-simulation FMU: fmuType must be fmi2CoSimulation");
            return nullptr;
        }
        std::string resources, none;
        try {
            resources = resource_dir_from_uri(resource_location);
            if (resources.empty())
                none = "fmuResourceLocation " +
                       std::string(resource_location != nullptr ? "\"" + utf8_excerpt(resource_location, 300) + "\""
                                                                : "NULL") +
                       " is not a local file URI";
        } catch (...) {
            call_logger(logger, instance_name, fmi2Error, LogCategory::error, "fmi2Instantiate: out of memory");
            return nullptr;
        }
        return create("fmi2Instantiate", instance_name, guid, logger, logging_on != fmi2False, resources, none);
    }

    static fmi2Status setup_experiment(fmi2Component c, fmi2Boolean /*tolerance_defined*/, fmi2Real /*tolerance*/,
                                       fmi2Real start, fmi2Boolean stop_defined, fmi2Real stop) noexcept {
        return guarded<M, fmi2_standard>(c, "fmi2SetupExperiment", mask(Phase::instantiated), [&](In& in) {
            set_experiment(in, start, stop_defined != fmi2False, stop);
            return fmi2OK;
        });
    }

    static fmi2Status get_directional_derivative(fmi2Component c, const fmi2ValueReference*, std::size_t,
                                                 const fmi2ValueReference*, std::size_t, const fmi2Real*,
                                                 fmi2Real*) noexcept {
        return guarded<M, fmi2_standard>(c, "fmi2GetDirectionalDerivative", kGet, [&](In&) -> fmi2Status {
            throw Error("not provided by this FMU (providesDirectionalDerivative=\"false\")");
        });
    }

    // --- co-simulation ---
    static fmi2Status set_real_input_derivatives(fmi2Component c, const fmi2ValueReference*, std::size_t,
                                                 const fmi2Integer*, const fmi2Real*) noexcept {
        return guarded<M, fmi2_standard>(c, "fmi2SetRealInputDerivatives", kSet, [&](In&) -> fmi2Status {
            throw Error("this FMU cannot interpolate inputs (canInterpolateInputs=\"false\")");
        });
    }

    static fmi2Status get_real_output_derivatives(fmi2Component c, const fmi2ValueReference*, std::size_t,
                                                  const fmi2Integer*, fmi2Real*) noexcept {
        return guarded<M, fmi2_standard>(
            c, "fmi2GetRealOutputDerivatives", mask(Phase::step_complete, Phase::terminated, Phase::error),
            [&](In&) -> fmi2Status {
                throw Error("this FMU provides no output derivatives (maxOutputDerivativeOrder=\"0\")");
            });
    }

    static fmi2Status do_step(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean /*no_set_state_prior*/) noexcept {
        return guarded<M, fmi2_standard>(c, "fmi2DoStep", mask(Phase::step_complete), [&](In& in) {
            step(in, t, h);
            return fmi2OK;
        });
    }

    static fmi2Status cancel_step(fmi2Component c) noexcept {
        return guarded<M, fmi2_standard>(c, "fmi2CancelStep", kAnyButFatal, [&](In&) -> fmi2Status {
            throw Error("fmi2DoStep computes synchronously and never returns fmi2Pending: there is no step to cancel");
        });
    }

    // The status queries. `answers` is the one kind this function reports (-1: none): a Real
    // fmi2LastSuccessfulTime, a Boolean fmi2Terminated (always false: the FMU never asks to stop).
    template <class V>
    static fmi2Status status(fmi2Component c, const char* fn, fmi2StatusKind s, V* value, int answers) noexcept {
        const int kind = enum_value(s);
        return guarded<M, fmi2_standard>(c, fn, kStatus, [&](In& in) {
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
