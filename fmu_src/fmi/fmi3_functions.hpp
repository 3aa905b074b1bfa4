// The FMI 3.0 co-simulation functions for a model M, as static members of Fmi3<M>: those FMI 2.0
// shares (glue_functions.hpp) and FMI 3.0's own; fmi3_entry_points.inc exports them under their C
// names, with every other FMI 3.0 function (model exchange, scheduled execution, clocks, event
// mode, derivatives), which returns fmi3Error and logs why. README.md in this folder specifies
// what each function accepts and refuses.
#pragma once

#include <cstddef>
#include <string>

#include "fmi3Functions.h"
#include "glue_functions.hpp"

namespace fmi::glue {

// The glue's statuses are fmi2Status; FMI 3.0 numbers the same statuses the same way.
static_assert(static_cast<int>(fmi2OK) == static_cast<int>(fmi3OK) &&
                  static_cast<int>(fmi2Warning) == static_cast<int>(fmi3Warning) &&
                  static_cast<int>(fmi2Discard) == static_cast<int>(fmi3Discard) &&
                  static_cast<int>(fmi2Error) == static_cast<int>(fmi3Error) &&
                  static_cast<int>(fmi2Fatal) == static_cast<int>(fmi3Fatal),
              "fmi2Status and fmi3Status must agree");
inline fmi3Status to_fmi3(fmi2Status s) { return static_cast<fmi3Status>(s); }

// FMI 3.0's resourcePath is a native directory path ending with a separator; the models join
// file names to it with '/', so the separator is dropped ("" stays "": no resources directory).
inline std::string resource_dir_from_path(const char* path) {
    if (path == nullptr) return "";
    std::string dir(path);
    while (dir.size() > 1 && (dir.back() == '/' || dir.back() == '\\')) dir.pop_back();
    return dir;
}

template <class M>
struct Fmi3 : Functions<M, fmi3_standard> {
    using In = Instance<M>;
    using Functions<M, fmi3_standard>::create;
    using Functions<M, fmi3_standard>::set_experiment;
    using Functions<M, fmi3_standard>::step;

    static fmi3Instance instantiate_co_simulation(fmi3String instance_name, fmi3String token, fmi3String resource_path,
                                                  fmi3Boolean logging_on, fmi3Boolean event_mode_used,
                                                  std::size_t n_required_intermediate_variables,
                                                  fmi3InstanceEnvironment env, fmi3LogMessageCallback log) noexcept {
        const Logger logger{nullptr, log, env};
        const char* fn = "fmi3InstantiateCoSimulation";
        if (event_mode_used || n_required_intermediate_variables > 0) {
            call_logger(
                logger, instance_name, fmi2Error, LogCategory::error,
                std::string(fn) + ": " + M::model_identifier +
                    (event_mode_used ? " has no Event Mode (hasEventMode=\"false\"): eventModeUsed must be false"
                                     : " provides no intermediate update (providesIntermediateUpdate="
                                       "\"false\"): nRequiredIntermediateVariables must be 0"));
            return nullptr;
        }
        std::string resources;
        try {
            resources = resource_dir_from_path(resource_path);
        } catch (...) {
            call_logger(logger, instance_name, fmi2Error, LogCategory::error, std::string(fn) + ": out of memory");
            return nullptr;
        }
        return create(fn, instance_name, token, logger, logging_on, resources,
                      resource_path == nullptr ? "resourcePath is NULL" : "resourcePath is empty");
    }

    // For model exchange and scheduled execution: no instance, the reason logged.
    static fmi3Instance instantiate_other(const char* fn, fmi3String instance_name, fmi3InstanceEnvironment env,
                                          fmi3LogMessageCallback log) noexcept {
        call_logger(Logger{nullptr, log, env}, instance_name, fmi2Error, LogCategory::error,
                    std::string(fn) + ": " + M::model_identifier +
                        " is a co-simulation FMU only: use fmi3InstantiateCoSimulation");
        return nullptr;
    }

    static fmi3Status enter_initialization_mode(fmi3Instance c, fmi3Float64 start, fmi3Boolean stop_defined,
                                                fmi3Float64 stop) noexcept {
        return to_fmi3(
            guarded<M, fmi3_standard>(c, "fmi3EnterInitializationMode", mask(Phase::instantiated), [&](In& in) {
                set_experiment(in, start, stop_defined, stop);
                in.phase = Phase::initialization_mode;
                return fmi2OK;
            }));
    }

    static fmi3Status do_step(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean* event_handling_needed,
                              fmi3Boolean* terminate_simulation, fmi3Boolean* early_return,
                              fmi3Float64* last_successful_time) noexcept {
        return to_fmi3(guarded<M, fmi3_standard>(c, "fmi3DoStep", mask(Phase::step_complete), [&](In& in) {
            if (event_handling_needed == nullptr || terminate_simulation == nullptr || early_return == nullptr ||
                last_successful_time == nullptr)
                throw Error(
                    "eventHandlingNeeded, terminateSimulation, earlyReturn and lastSuccessfulTime must not be "
                    "NULL");
            // Never an event, never a request to stop, never an early return: the step is whole.
            *event_handling_needed = fmi3False;
            *terminate_simulation = fmi3False;
            *early_return = fmi3False;
            *last_successful_time = in.time;
            step(in, t, h);
            *last_successful_time = in.time;
            return fmi2OK;
        }));
    }

    // Configuration Mode: where structural parameters (an array's lengths) are set, from
    // Instantiated and back to it.
    static fmi3Status enter_configuration_mode(fmi3Instance c) noexcept {
        return to_fmi3(
            guarded<M, fmi3_standard>(c, "fmi3EnterConfigurationMode", mask(Phase::instantiated), [&](In& in) {
                in.phase = Phase::configuration_mode;
                return fmi2OK;
            }));
    }
    static fmi3Status exit_configuration_mode(fmi3Instance c) noexcept {
        return to_fmi3(
            guarded<M, fmi3_standard>(c, "fmi3ExitConfigurationMode", mask(Phase::configuration_mode), [&](In& in) {
                in.phase = Phase::instantiated;
                return fmi2OK;
            }));
    }

    // A Get or Set of a type this FMU has no variable of (Float32, the 8-, 16- and 64-bit and
    // unsigned integers, Binary, Clock): nothing to do for no value reference, else refused.
    static fmi3Status no_variable_of_type(fmi3Instance c, const char* fn, PhaseMask allowed, const char* type,
                                          const fmi3ValueReference vr[], std::size_t nvr) noexcept {
        return to_fmi3(guarded<M, fmi3_standard>(c, fn, allowed, [&](In&) {
            if (nvr == 0) return fmi2OK;
            throw Error(std::string(M::model_identifier) + " has no " + type + " variable" +
                        (vr != nullptr ? " (value reference " + std::to_string(vr[0]) + ")" : std::string()));
        }));
    }

    // A function of a capability this FMU does not have: refused in every state but fatal.
    static fmi3Status unsupported(fmi3Instance c, const char* fn, const char* why) noexcept {
        return to_fmi3(guarded<M, fmi3_standard>(c, fn, kAnyButFatal, [&](In&) -> fmi2Status { throw Error(why); }));
    }
};

}  // namespace fmi::glue
