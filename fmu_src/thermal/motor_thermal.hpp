// The machine's thermal state over a run: the network's node temperatures and the heat balance's
// integrals, advanced once per communication step by the exact step of thermal_network.hpp with
// the losses' integrals over the step (their means as constant sources: all the heat the losses
// put in enters the network exactly). Plain data plus a propagator cache, so copies and
// serialisation are exact.
#pragma once

#include "thermal/motor_lptn.hpp"

namespace ipmsm::thermal {

// What one step of the machine sees, held over the step (as an FMU holds its inputs).
struct StepConditions {
    double w_m = 0.0;           // rad/s, mechanical speed (conductances, iron-loss split)
    double I_rms = 0.0;         // A, RMS phase current (iron-loss split)
    double T_coolant = 293.15;  // K
    double T_ambient = 293.15;  // K
};

class MotorThermal {
public:
    // The nodes start at theta0 (K, each, or all at one); throws std::invalid_argument on bad
    // parameters or temperatures.
    MotorThermal(const LptnParams& p, const NodeVector& theta0);
    MotorThermal(const LptnParams& p, double theta0) : MotorThermal(p, NodeVector::Constant(theta0)) {}

    // Advances by h (s) with the copper and iron losses' integrals over the step (J).
    void advance(double h, double E_cu_step, double E_fe_step, const StepConditions& at);

    double theta(Node i) const { return theta_[i]; }
    const NodeVector& theta() const { return theta_; }
    double E_loss() const { return E_loss_; }                  // J, heat put in since the start
    double E_coolant() const { return E_boundary_[coolant]; }  // J, heat into the coolant since the start
    double E_ambient() const { return E_boundary_[ambient]; }  // J, heat into the ambient air since the start
    double E_stored() const;                                   // J, sum C_i (theta_i - theta_i(0))
    double P_coolant() const { return P_coolant_; }            // W, mean heat into the coolant over the last step
    const MotorPropagator& propagator() const { return propagator_; }

    // The state a step changes, in the order it is serialised (an FMU's state fields), each node
    // temperature with what it may hold (K); the energies finite, and then their balance closes
    // (heat_balance_error).
    template <class Field, class Range>
    void state_fields(Field&& field, const Range& temperature) {
        for (int i = 0; i < kNodes; ++i) field(theta_[i], temperature);
        for (int i = 0; i < kNodes; ++i) field(theta0_[i], temperature);
        field(E_loss_), field(E_boundary_[coolant]), field(E_boundary_[ambient]), field(P_coolant_);
    }
    // |E_loss - E_stored - E_coolant - E_ambient| relative to the largest of them (J/J; 0 if all
    // are 0): the exact step conserves energy to rounding, so a state whose balance does not close
    // is not one this network reached.
    double heat_balance_error() const;

private:
    LptnParams p_;
    MotorPropagator propagator_;
    NodeVector theta_, theta0_;
    double E_loss_ = 0.0;
    BoundaryVector E_boundary_ = BoundaryVector::Zero();
    double P_coolant_ = 0.0;
};

}  // namespace ipmsm::thermal
