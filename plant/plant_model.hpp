// IpmsmPlant: the saturated IPMSM's electrical dynamics on a flux map, integrated by CVODE.
// The model of the IpmsmPlant FMU; free of FMI types (the glue in ../fmu_src/fmi maps it).
//
// States psi_d, psi_q; currents the map's exact inverse (its table built at initialisation);
// d psi_d/dt = u_d - R i_d + omega psi_q, d psi_q/dt = u_q - R i_q - omega psi_d with the inputs
// held over each communication step (ipmsm_ode.hpp). Each step is linearised at its start and
// CVODE (Adams, functional iteration) integrates what the exact linear flow misses, from
// tau = 0 to h (relative time); it is re-initialised at every communication point, so the
// model's whole state is plain data and copies, FMU-state rollback and serialisation are exact
// (cvode_integrator.hpp).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "cvode_integrator.hpp"
#include "freewheel_integrator.hpp"
#include "inverter/inverter_loss.hpp"
#include "inverter_state.hpp"
#include "ipmsm_ode.hpp"
#include "machine/flux_map.hpp"
#include "machine/inverse_flux_map.hpp"
#include "machine/iron_loss.hpp"
#include "machine/motor_params.hpp"
#include "model.hpp"
#include "thermal/motor_thermal.hpp"
#include "variable.hpp"

namespace ipmsm {

class PlantModel {
public:
    static constexpr const char* model_identifier = "IpmsmPlant";
    static constexpr const char* guid = "{2acdb2e1-861a-46f0-8fab-2d079ed2d3fa}";
    static constexpr const char* description =
        "Saturated interior-PM synchronous motor: dq flux linkages as states on a flux map "
        "(currents from the inverse map), magnet and winding temperatures, torque, shaft torque "
        "with iron-loss drag, powers and losses; integrated by CVODE.";
    static constexpr double default_step_size = 1e-4;
    static constexpr double default_stop_time = 0.1;
    static const std::vector<fmi::Variable<PlantModel>>& variables();

    // The inputs each output depends on at initialisation (fmi/model_description.hpp): the
    // currents come from the start currents and the magnet's temperature, never from the
    // voltages (so a master sees no loop with the controller at initialisation).
    static std::vector<std::pair<std::string, std::vector<std::string>>> initial_inputs() {
        const std::vector<std::string> magnet{"T_magnet"};
        return {{"i_d", magnet},
                {"i_q", magnet},
                {"psi_d", magnet},
                {"psi_q", magnet},
                {"T_e", magnet},
                {"psi_m_T", magnet},
                {"T_shaft", {"w_m", "T_magnet"}},
                {"P_mech", {"w_m", "T_magnet"}},
                {"P_fe", {"w_m", "T_magnet"}},
                {"P_cu", {"T_magnet", "T_winding"}},
                {"P_elec", {"u_d", "u_q", "T_magnet"}},
                {"R_s_T", {"T_winding"}},
                {"theta_winding", {"T_winding"}},
                {"theta_magnet", {"T_magnet"}},
                {"theta_stator_yoke", {"T_winding"}},
                {"theta_stator_tooth", {"T_winding"}},
                {"P_coolant", {}},
                {"E_coolant", {}},
                {"E_ambient", {}},
                {"E_stored", {}},
                {"E_elec", {}},
                {"E_mech", {}},
                {"E_cu", {}},
                {"E_fe", {}},
                {"T_e_impulse", {}},
                {"P_inv", {"u_d", "u_q", "u_dc", "T_magnet"}},
                {"E_inv", {}},
                {"cvode_steps", {}},
                {"cvode_rhs_evals", {}}};
    }

    explicit PlantModel(const fmi::Context& context);
    void exit_initialization();
    void do_step(double t, double h);
    // The state a step changes beyond the variables (model.hpp), in the order it is serialised.
    // Each field with what it may hold (a state is input, not proof: fmi/model.hpp).
    template <class Field>
    void state_fields(Field&& field) {
        const StateRanges r = state_ranges();
        CvodeState s = integrator_.state();
        field(s.t), field(s.psi, r.flux), field(s.h_next, r.step), field(s.i_seed, r.current);
        integrator_.set_state(s);  // what was read in; the same state when the fields were written
        field(outside_warned_);
        field(blocked_), field(demag_warned_);
        MapContent saved = map_content(map_.get());  // written as is; read: the map must be the same
        field(saved);
        check_map_content(saved, map_.get());
        if (thermal_) {  // thermal_model is a fixed parameter: same fields both ways
            thermal_->state_fields(field, r.temperature);
            check_thermal_state();
        }
    }

    // --- inputs
    double u_d = 0.0, u_q = 0.0;  // V
    double w_m = 0.0;             // rad/s
    double T_magnet = 293.15;     // K
    double T_winding = 293.15;    // K
    double T_coolant = 293.15;    // K, the thermal network's coolant (thermal_model)
    double T_ambient = 293.15;    // K, the thermal network's ambient air (thermal_model)
    double u_dc = 355.0;          // V, the DC link the inverter switches (its loss: P_inv)
    int inverter_state = 0;       // InverterState: 0 switching, 1 freewheeling, 2 ASC (inverter_state.hpp)
    // --- outputs
    double i_d = 0.0, i_q = 0.0;                                // A
    double psi_d = 0.0, psi_q = 0.0;                            // Wb
    double T_e = 0.0, T_shaft = 0.0;                            // N.m
    double P_elec = 0.0, P_mech = 0.0, P_cu = 0.0, P_fe = 0.0;  // W
    double psi_m_T = 0.0;                                       // Wb, PM flux at T_magnet
    double R_s_T = 0.0;                                         // Ohm, R_s at T_winding
    // integrals since the start, exact over each step (CVODE quadratures: cvode_integrator.hpp)
    double E_elec = 0.0, E_mech = 0.0, E_cu = 0.0, E_fe = 0.0;  // J
    double T_e_impulse = 0.0;                                   // N.m.s, int T_e dt
    // the thermal network (thermal_model; off: the temperature inputs, no heat flows)
    double theta_winding = 293.15, theta_magnet = 293.15;            // K
    double theta_stator_yoke = 293.15, theta_stator_tooth = 293.15;  // K
    double P_coolant = 0.0;                                          // W, mean heat into the coolant over the step
    double E_coolant = 0.0, E_ambient = 0.0, E_stored = 0.0;         // J since the start
    // the inverter feeding the machine (inverter/inverter_loss.hpp): its loss over the last step,
    // from the current sampled at the step's end and the step's mean AC power, and since the start
    double P_inv = 0.0;         // W
    double E_inv = 0.0;         // J
    double i_dc = 0.0;          // A, the DC-link current of the last step, losses included (+ motoring)
    int bridge_switchings = 0;  // freewheeling: the bridge's conduct/block switchings since the start
    int cvode_steps = 0;        // internal steps in the last step
    int cvode_rhs_evals = 0;    // right-hand-side evaluations in the last step
    // --- parameters (defaults: the default motor, fmu_src/resources/ev_ipmsm_default.csv)
    MotorParams motor;                                // the motor (machine/motor_params.hpp), as the controller's
    IronLossModel iron_loss = kDefaultMotorIronLoss;  // its iron loss (machine/iron_loss.hpp)
    double i_d_start = 0.0, i_q_start = 0.0;          // A
    double i_d_demag = 0.0;                           // A, the magnets' demagnetisation limit on i_d (< 0; 0: none)
    double rtol = 1e-6;
    double atol = 1e-8;           // Wb (what CVODE's error control sees: cvode_integrator.hpp)
    int cvode_method = 1;         // 1 Adams (functional iteration), 2 BDF (Newton, analytic Jacobian)
    int cvode_max_order = 0;      // 0: the method's maximum
    int cvode_max_steps = 20000;  // per communication step
    bool thermal_model = false;   // the thermal network sets T_winding, T_magnet (docs/thermal.md)
    thermal::LptnParams lptn;     // its parameters (forwarded by name)
    InverterParams inverter;      // the inverter's loss model's parameters (forwarded by name)

    // Not a variable: false lets a model that holds the plant (IpmsmDrive) advance the network
    // once per its own communication step (advance_thermal) instead of at every plant step.
    bool thermal_each_step = true;
    bool thermal_on() const { return thermal_.has_value(); }
    // Heats the network over h (s) with the loss integrals E_cu_step, E_fe_step (J), at the present
    // speed, currents and boundary temperatures; updates the thermal outputs.
    void advance_thermal(double h, double E_cu_step, double E_fe_step);

    // The back-EMF's line-to-line peak at zero current, sqrt 3 |p w_m| |psi(0, 0)| (V, the magnets'
    // flux at the present magnet temperature): the diode bridge conducts once it exceeds u_dc
    // (docs/faults.md). The model must be initialised.
    double back_emf_line_peak() const;

private:
    // What the internal state may hold: fluxes the machine on the map reaches (flux_reach), Newton
    // seeds within kSeedReach of the grid's currents, a step size >= 0, node temperatures those
    // both FMUs accept (machine.hpp).
    struct StateRanges {
        fmi::FieldRange flux, current, step, temperature;
    };
    StateRanges state_ranges() const;
    // The network's outputs are its state's (throws fmi::Error).
    void check_thermal_state() const;

    DqFluxOde ode() const;  // the right-hand side for the present inputs (throws if invalid)
    void update_outputs(const DqFluxOde& ode);
    void update_outputs(const DqFluxOde& ode, double i_d, double i_q);  // at currents known exactly
    CvodeSettings settings() const;
    StepIntegrands integrands() const;
    double winding_temperature() const { return thermal_ ? thermal_->theta(thermal::winding) : T_winding; }
    double magnet_temperature() const { return thermal_ ? thermal_->theta(thermal::magnet) : T_magnet; }
    void update_thermal_outputs();
    // The inverter's loss (W) at the present currents (the sample at a step's end), with the mean
    // AC power P_ac (W) and u_dc.
    double inverter_loss_now(double P_ac) const;
    // One step of h freewheeling (freewheel_integrator.hpp) from the step's start state.
    void freewheel_step(const DqFluxOde& o, double h);
    // o with the voltage at the terminals in the present inverter_state at the currents i: the
    // inputs (switching), zero (ASC), the diode bridge's (freewheeling; zero while blocked).
    DqFluxOde terminal_voltage(DqFluxOde o, double i_d_now, double i_q_now) const;
    // The inverter's loss (W) in the present inverter_state: the switching model at the mean AC
    // power P_ac; the diodes' at the mean |i| = I and |i|^2 = I2 (freewheeling); none (ASC).
    double inverter_loss_in_state(double P_ac, double I, double I2) const;
    void warn_demagnetising(double t);

    fmi::SharedContext context_;
    std::shared_ptr<const FluxMap> map_;
    std::shared_ptr<const InverseFluxMap> inverse_;
    CvodeIntegrator integrator_;
    std::optional<thermal::MotorThermal> thermal_;  // thermal_model: made at initialisation
    bool outside_warned_ = false;                   // the currents left the map's grid (warned once per excursion)
    FreewheelIntegrator freewheel_;                 // scratch (its state is the plant's)
    bool blocked_ = false;                          // freewheeling: the bridge blocks, i = 0
    bool demag_warned_ = false;                     // i_d passed i_d_demag (warned once)
};

}  // namespace ipmsm
