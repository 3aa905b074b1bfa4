// IpmsmController: torque command -> current-minimising current commands -> voltage commands.
// The model of the IpmsmController FMU; free of FMI types (the glue in ../fmi maps it).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "control/current_regulator.hpp"
#include "control/derating.hpp"
#include "control/least_loss.hpp"
#include "control/saturated_optimal_current.hpp"
#include "control/torque_table.hpp"
#include "losses/drive_loss.hpp"
#include "machine/motor_params.hpp"
#include "model.hpp"
#include "variable.hpp"

namespace ipmsm {

class ControllerModel {
public:
    static constexpr const char* model_identifier = "IpmsmController";
    static constexpr const char* guid = "{8d3c5f0e-2b7a-4c61-9e44-1f5a7b2c9d01}";
    static constexpr const char* description =
        "IPMSM torque controller: current-minimising d/q current commands by Ferrari's method "
        "(MTPA, voltage ellipse with R_s, MTPV, torque clamping) with inductance recursion on a "
        "flux map, or the 2-D lookup-table baseline; and a PI current regulator.";
    static constexpr double default_step_size = 1e-4;
    static constexpr double default_stop_time = 0.1;
    static const std::vector<fmi::Variable<ControllerModel>>& variables();

    explicit ControllerModel(const fmi::Context& context);
    void exit_initialization();
    void do_step(double t, double h);
    // The observations of the measured state, T_est and u_ratio, from the present inputs and
    // voltage command. do_step sets them unless observe_each_step is false: a model that steps
    // the controller many times per communication step (IpmsmDrive) and reads them only at its
    // end calls observe() then.
    void observe();
    bool observe_each_step = true;
    // The current regulator stopped while the inverter does not switch (IpmsmDrive in a fault,
    // docs/faults.md): its state restarts from the measured currents i_d, i_q as at initialisation
    // (integrator empty, the voltage command the one that holds them: a flying start), so that
    // switching resumes from the currents the fault left, without a torque jump.
    void restart_regulator();
    // The state a step changes beyond the variables (model.hpp), in the order it is serialised.
    template <class Field>
    void state_fields(Field&& field) {
        SolverMemory unused;  // before initialisation there is no solver, and no memory to keep
        (solver_ ? solver_->memory : unused).fields(field);
        regulator_.state.fields(field);
        field(warned_unreachable_);
        field(check_failures), field(warned_check_);
        cache_.fields(field);
        MapContent saved = map_content(map_.get());  // written as is; read: the map must be the same
        field(saved);
        check_map_content(saved, map_.get());
    }

    // --- inputs
    double T_ref = 0.0;           // N.m
    double w_m = 0.0;             // rad/s
    double u_dc = 355.0;          // V
    double i_d = 0.0, i_q = 0.0;  // A, measured
    double T_magnet = 293.15;     // K
    double T_winding = 293.15;    // K: its R_s follows it
    // --- outputs
    double i_d_ref = 0.0, i_q_ref = 0.0;           // A
    double u_d_ref = 0.0, u_q_ref = 0.0;           // V
    double T_cmd = 0.0, T_max = 0.0, T_est = 0.0;  // N.m
    int region = 0;
    int iterations = 0;
    bool voltage_saturated = false;
    double u_ratio = 0.0;  // |u_ref| / (u_dc / sqrt 3): use of the inverter's linear range
    int table_bytes = 0;
    int check_failures = 0;   // commands that failed the check on the map (docs/controller.md)
    double derating = 1.0;    // the torque limit's thermal factor (1: none)
    double P_loss_cmd = 0.0;  // W, the command's predicted steady-state loss P_cu + P_fe + P_inv
    // --- parameters (defaults: the default motor, fmu_src/resources/ev_ipmsm_default.csv)
    int method = 1;     // 1 Ferrari, 2 table over torque x speed, 3 table over torque x V_max/omega
    int recursion = 2;  // 0 nominal inductances, 1 the paper's recursion, 2 optimal on the map
    MotorParams motor;  // the motor (machine/motor_params.hpp), shared with the plant's declaration
    double k_u = 0.95;
    double lut_u_dc = 355.0;       // V
    double lut_T_magnet = 293.15;  // K
    int lut_n_torque = 41;
    int lut_n_speed = 41;
    double w_m_max = 1256.6370614359173;            // rad/s (12 000 r/min): top of the tables' speed axis
    double current_bandwidth = 3141.5926535897932;  // rad/s (500 Hz)
    int command_check = 1;  // 1: failing commands replaced; 0: reported only (docs/controller.md)
    // Derating (docs/thermal.md, "Controller"): the winding's limit is IEC 60085's thermal class
    // 180 (H), the magnets' the maximum operating temperature of sintered NdFeB of the SH grades
    // (150 degC), and each derates over the 25 K from class 155 (F) to class 180 (H).
    double T_winding_max = 453.15;  // K
    double T_magnet_max = 423.15;   // K
    double derating_margin = 25.0;  // K
    // Least-loss control (docs/spec/MATH.md, "Least-loss control"): 0 least current (the seed's),
    // 1 least loss (T_cmd, T_max are then shaft torques); the loss models' parameters, the
    // plant's parts (parts/part_variables.cpp: the same names, ranges and defaults).
    int objective = 0;
    IronLossModel iron_loss = kDefaultMotorIronLoss;
    InverterParams inverter;

private:
    // omega (electrical), V_max, the magnet's psi_d shift, the winding's resistance and the
    // thermal derating, from the inputs and parameters.
    struct Conditions {
        double omega, V_max, shift, R, derating;
    };
    Conditions conditions() const;
    CurrentCommand current_command(const Conditions& c);            // reuses the cache while it holds
    CurrentCommand checked_command(double T, const Conditions& c);  // for the torque T, checked on the map
    // the command outputs (u_*_ref set); derating_now: the conditions' derating
    void publish(const CurrentCommand& cmd, const MagnetFlux& flux, double derating_now);
    void observe(const MagnetFlux& flux);
    void initial_outputs();
    // The voltage that holds the measured currents (R i + j omega psi(i)) within the inverter's
    // linear range, as the regulator's voltage being applied and the command (a flying start).
    void flying_start_voltage(const Conditions& c, const MagnetFlux& flux);
    void report_check(const CheckRecord& r);                           // counts; logs the first
    DriveLoss drive_loss(const Conditions& c) const;                   // the loss model at the present conditions
    CurrentCommand least_loss_command(double T, const Conditions& c);  // objective 1, checked

    // The last command and the inputs it was solved for: while T_ref, w_m, u_dc, T_magnet and
    // T_winding stay bit-identical (a master holding its slow inputs), the problem, and so its solution,
    // is the same, and is not solved again.
    struct CommandCache {
        bool valid = false;
        double T_ref = 0, w_m = 0, u_dc = 0, T_magnet = 0, T_winding = 0;
        CurrentCommand cmd;
        bool holds(const ControllerModel& m) const {
            return valid && T_ref == m.T_ref && w_m == m.w_m && u_dc == m.u_dc && T_magnet == m.T_magnet &&
                   T_winding == m.T_winding;
        }
        template <class Field>
        void fields(Field&& field) {
            field(valid), field(T_ref), field(w_m), field(u_dc), field(T_magnet), field(T_winding);
            cmd.fields(field);
        }
    };
    CommandCache cache_;

    fmi::SharedContext context_;
    std::shared_ptr<const FluxMap> map_;
    std::shared_ptr<const TorqueTable> table_;
    std::optional<SaturatedOptimalCurrent> solver_;  // its warm-start memory is state
    std::optional<LeastLoss> least_loss_;            // objective 1 (no state: a function of the inputs)
    CurrentRegulator regulator_{0.0, 0.0};
    bool warned_unreachable_ = false;
    bool warned_check_ = false;
};

}  // namespace ipmsm
