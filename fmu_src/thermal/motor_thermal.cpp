#include "thermal/motor_thermal.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace ipmsm::thermal {

namespace {
LptnParams validated(const LptnParams& p) {
    validate(p);
    return p;
}
}  // namespace

MotorThermal::MotorThermal(const LptnParams& p, const NodeVector& theta0)
    : p_(validated(p)), propagator_(capacities(p_)) {
    for (int i = 0; i < kNodes; ++i)
        if (!(std::isfinite(theta0[i]) && theta0[i] > 0.0))
            throw std::invalid_argument("thermal network: initial temperature " + std::to_string(theta0[i]) + " K");
    theta_ = theta0;
    theta0_ = theta0;
}

void MotorThermal::advance(double h, double E_cu_step, double E_fe_step, const StepConditions& at) {
    if (!(std::isfinite(h) && h > 0.0)) throw std::invalid_argument("thermal network: step length must be > 0");
    // (finite, not >= 0: a quadrature's rounding may leave a zero loss at -1e-20 J; it enters the
    // balance as it is)
    if (!(std::isfinite(E_cu_step) && std::isfinite(E_fe_step)))
        throw std::invalid_argument("thermal network: losses over a step must be finite");
    if (!(std::isfinite(at.T_coolant) && at.T_coolant > 0.0 && std::isfinite(at.T_ambient) && at.T_ambient > 0.0))
        throw std::invalid_argument("thermal network: boundary temperatures must be finite and > 0 K");
    propagator_.set_conductances(conductances(p_, at.w_m, at.T_coolant));
    const NodeVector P = node_losses(p_, E_cu_step / h, E_fe_step / h, at.w_m, at.I_rms);
    BoundaryVector theta_b;
    theta_b[coolant] = at.T_coolant;
    theta_b[ambient] = at.T_ambient;
    const auto heat = propagator_.step(theta_, P, theta_b, h);
    theta_ = heat.theta;
    E_loss_ += E_cu_step + E_fe_step;
    E_boundary_ += heat.boundary;
    P_coolant_ = heat.boundary[coolant] / h;
}

double MotorThermal::heat_balance_error() const {
    const double stored = E_stored();
    // E_stored is a difference of temperatures near 300 K: its rounding is relative to the heat
    // the nodes hold, sum C_i (|theta_i| + |theta0_i|), not to E_stored itself (a network at its
    // boundaries' temperature with no loss has every energy ~0 and E_stored a few ulps of that)
    const NodeVector C = capacities(p_);
    const double held = C.dot(theta_.cwiseAbs() + theta0_.cwiseAbs());
    const double scale = std::max({std::abs(E_loss_), std::abs(stored), std::abs(E_boundary_[coolant]),
                                   std::abs(E_boundary_[ambient]), held * std::numeric_limits<double>::epsilon()});
    if (scale == 0.0) return 0.0;
    return std::abs(E_loss_ - stored - E_boundary_[coolant] - E_boundary_[ambient]) / scale;
}

double MotorThermal::E_stored() const { return capacities(p_).dot(theta_ - theta0_); }

}  // namespace ipmsm::thermal
