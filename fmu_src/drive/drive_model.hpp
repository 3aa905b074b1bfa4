// IpmsmDrive: the controller and the plant coupled inside one FMU at sample_time, for
// vehicle-level tools that step at 1-10 ms. The model of the IpmsmDrive FMU, free of FMI types.
//
// It holds a ControllerModel and a PlantModel and runs them through the drive's one coupling
// description (coupling/ipmsm_drive.coupling, by coupling/coupled_models.hpp): the same inner
// sequence of calls as the two FMUs coupled by a master at sample_time. A communication step of
// n sample times returns the means over it of the plant's torques and powers, exact: the plant
// integrates them over each inner step (its E_* and T_e_impulse outputs, CVODE quadratures), the
// means are their increases over the step; the inverter's loss (the plant's, inverter/inverter_loss.hpp),
// per inner step, and the DC current; and the energies since the start, so that a master at 10 ms
// loses nothing between its samples: E_dc = E_mech + E_cu + E_fe + E_inv + Delta W_magnetic.
//
// Parameters: every parameter of the two models, once, by the same name, forwarded to the models
// that hold it (value, unit, range and description from the models' tables: one source; the
// inverter's are the plant's); and sample_time.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "controller/controller_model.hpp"
#include "coupling/coupled_models.hpp"
#include "model.hpp"
#include "plant_model.hpp"
#include "variable.hpp"

namespace ipmsm {

class DriveModel {
public:
    static constexpr const char* model_identifier = "IpmsmDrive";
    static constexpr const char* guid = "{5b0f6d2a-93c4-4e1b-8a77-0c2e9d4f6b13}";
    static constexpr const char* description =
        "IPMSM traction drive: the IpmsmController and the IpmsmPlant coupled inside at sample_time "
        "(any whole multiple of it is a communication step), with the inverter's conduction and "
        "switching losses; step means and integrals of the shaft torque, DC current, powers and losses.";
    static constexpr double default_step_size = 1e-3;
    static constexpr double default_stop_time = 1.0;
    static const std::vector<fmi::Variable<DriveModel>>& variables();

    explicit DriveModel(const fmi::Context& context);
    void exit_initialization();
    void do_step(double t, double h);
    template <class Field>
    void state_fields(Field&& field) {
        // exact below 2^53 steps; the stream has no 64-bit integers: a count, checked before the cast
        double k = static_cast<double>(k_);
        field(k, fmi::FieldRange{"the drive's inner step count", 0.0, kMaxInnerSteps, true});
        k_ = static_cast<long long>(k);
        sub_model_fields(controller_, field);
        check_voltage_command();
        sub_model_fields(plant_, field);
        controller_.state_fields(field);
        plant_.state_fields(field);
    }

    // --- inputs (held over the communication step)
    double T_ref = 0.0, w_m = 0.0, u_dc = 0.0, T_magnet = 0.0, T_winding = 0.0;
    double T_coolant = 0.0, T_ambient = 0.0;  // K, the plant's thermal network (thermal_model)
    bool fault = false;                       // the inverter must stop switching (docs/faults.md)
    // --- outputs: the inverter's safe states (docs/faults.md)
    int inverter_state = 0;  // InverterState the plant is in over the last step
    double i_peak = 0.0;     // A, the largest |i| at the inner steps' ends since the last fault began
    // --- outputs: means over the last communication step
    double T_shaft = 0.0, T_e = 0.0, i_dc = 0.0;                           // N.m, N.m, A
    double P_dc = 0.0, P_mech = 0.0, P_cu = 0.0, P_fe = 0.0, P_inv = 0.0;  // W
    double P_elec = 0.0;  // W, the machine's electrical input (P_dc - P_inv)
    // --- outputs: integrals since the start
    double E_dc = 0.0, E_mech = 0.0, E_cu = 0.0, E_fe = 0.0, E_inv = 0.0;  // J
    // --- outputs at the end of the step: the models' own, forwarded (drive_model.cpp, variables())
    // --- parameters: the drive's own (the others live in controller_ and plant_)
    double sample_time = 1e-4;  // s
    // K: the controller's magnet temperature is the machine's (the network's, or the T_magnet
    // input) plus this, as a drive estimates it (docs/thermal.md, "Controller")
    double T_magnet_estimate_error = 0.0;
    int safe_state = 0;  // on a fault: 0 by speed, 1 freewheeling, 2 ASC (docs/faults.md)
    // The most inner steps one fmi2DoStep computes (10 s at the default sample_time): a step cannot be
    // interrupted, so a larger one is refused rather than computed for minutes.
    static constexpr double max_samples_per_step = 1e5;
    // The plant's internal steps one fmi2DoStep may take over all its inner steps (each at most
    // cvode_max_steps): with max_samples_per_step, what bounds a step's wall time at any parameter
    // in range (docs/spec/INTERFACE.md, "Bounded steps"). A 10 s step at the defaults takes about
    // 1e5; a step that needs more is refused, undone, and can be taken in parts.
    static constexpr double max_plant_steps_per_step = 5e5;
    // The longest sample_time: the current regulator closes its loop up to 0.9 of an electrical
    // turn per sample (control/current_regulator.hpp, kMaxRotationPerSample), which at 1 ms is
    // 12 000 r/min with 4 pole pairs, and its bandwidth is at most pi / (2 sample_time) (ibid.):
    // 250 Hz at 1 ms. A longer sample is no current loop (traction inverters sample at their PWM
    // frequency, 2-20 kHz); 0.2's 1 s let one sample run the plant open-loop for a second.
    static constexpr double kMaxSampleTime = 1e-3;

    // The sub-models' warnings given so far, each with the model that gave it first ("controller"
    // or "plant"): one given by both reaches the importer once (drive_model.cpp, prefixed()).
    using WarningsGiven = std::map<std::string, std::string>;

private:
    // 2^53: the largest count a double holds exactly
    static constexpr double kMaxInnerSteps = 9007199254740992.0;
    // The sub-model's inputs, outputs and locals (its coupled inputs and outputs are not the
    // drive's variables, but are state: the next inner step reads them), each checked against the
    // sub-model's table as its fmi2SetReal would check it. Its parameters are not: they are the
    // drive's (forwarded by name), restored and checked with the drive's variables.
    template <class Sub, class Field>
    static void sub_model_fields(Sub& sub, Field& field) {
        for (const auto& v : Sub::variables()) {
            if (v.causality == fmi::Causality::parameter || v.causality == fmi::Causality::structural_parameter)
                continue;
            std::visit(
                [&](const auto& a) {
                    using A = std::decay_t<decltype(a)>;
                    if constexpr (!std::is_same_v<A, fmi::Access<Sub, std::string>> &&
                                  !std::is_same_v<A, fmi::Access<Sub, std::vector<double>>> &&
                                  !std::is_same_v<A, fmi::Access<Sub, std::uint64_t>>)
                        if (a.member != nullptr) field(sub.*(a.member), v);
                },
                v.member);
        }
    }
    // The controller's voltage command, which the next inner step applies to the plant, is one the
    // regulator can give: within the inverter's linear range at the u_dc it was given for (throws
    // fmi::Error; a state is input, not proof).
    void check_voltage_command() const;
    coupling::CoupledModels& coupled();
    void hold_inputs();
    void publish_end();
    // The inverter's state for the next step from fault, safe_state and the present one.
    int next_inverter_state() const;

    std::shared_ptr<WarningsGiven> warnings_given_;  // shared by the models' contexts and the drive's copies
    ControllerModel controller_;
    PlantModel plant_;
    long long k_ = 0;  // inner steps since the start
    // The coupled models point into this object: a copy of the drive (undo, FMU states) starts
    // without them and builds its own on first use.
    struct CouplingCache {
        std::unique_ptr<coupling::CoupledModels> models;
        CouplingCache() = default;
        CouplingCache(const CouplingCache&) {}
        CouplingCache& operator=(const CouplingCache&) {
            models.reset();
            return *this;
        }
    };
    CouplingCache coupled_;
};

}  // namespace ipmsm
