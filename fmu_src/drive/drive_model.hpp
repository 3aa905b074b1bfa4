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
        double k = static_cast<double>(k_);  // exact below 2^53 steps; the stream has no 64-bit integers
        field(k);
        k_ = static_cast<long long>(k);
        sub_model_fields(controller_, field);
        sub_model_fields(plant_, field);
        controller_.state_fields(field);
        plant_.state_fields(field);
    }

    // --- inputs (held over the communication step)
    double T_ref = 0.0, w_m = 0.0, u_dc = 0.0, T_magnet = 0.0, T_winding = 0.0;
    double T_coolant = 0.0, T_ambient = 0.0;  // K, the plant's thermal network (thermal_model)
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
    // The most inner steps one fmi2DoStep computes (10 s at the default sample_time): a step cannot be
    // interrupted, so a larger one is refused rather than computed for minutes.
    static constexpr double max_samples_per_step = 1e5;

    // The sub-models' warnings given so far, each with the model that gave it first ("controller"
    // or "plant"): one given by both reaches the importer once (drive_model.cpp, prefixed()).
    using WarningsGiven = std::map<std::string, std::string>;

private:
    // The sub-model's variables (its coupled inputs and outputs are not the drive's variables,
    // but are state: the next inner step reads them).
    template <class Sub, class Field>
    static void sub_model_fields(Sub& sub, Field& field) {
        for (const auto& v : Sub::variables())
            std::visit(
                [&](const auto& a) {
                    // (a variable the sub-model forwards to a part of it lives in that part, which
                    // is fixed parameters only: the plant's thermal network's)
                    if constexpr (!std::is_same_v<decltype(a), const fmi::Access<Sub, std::string>&>)
                        if (a.member != nullptr) field(sub.*(a.member));
                },
                v.member);
    }
    coupling::CoupledModels& coupled();
    void hold_inputs();
    void publish_end();

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
