// Current-minimising commands for a constant-inductance IPMSM, all in closed form through
// Ferrari's quartic solver (quartic.hpp): MTPA (Case i), the voltage ellipse with R_s (Case ii),
// MTPA at the current limit, MTPV, and the current-circle / voltage-ellipse intersection.
//
// Torques are in "reduced" form T' = T / (1.5 p) (Wb.A). All functions take T' >= 0; the
// mirror symmetry (T, omega, i_q) -> (-T, -omega, -i_q) of the dq equations handles T < 0
// in optimal_current().
#pragma once

#include <cmath>

#include "machine/machine.hpp"

namespace ipmsm::linear {

using Point = CurrentPoint;

// Steady-state voltage magnitude squared at a current.
double voltage_sq(const LinearMachine& m, double omega, double i_d, double i_q);
// Reduced torque psi_m i_q + (L_d - L_q) i_d i_q.
double reduced_torque(const LinearMachine& m, double i_d, double i_q);

// Case i: the minimum-current point for T' >= 0 (seed eq. (16), solved in its i_q form).
Point mtpa(const LinearMachine& m, double T_red);
// MTPA for a current magnitude I (closed form).
Point mtpa_at_current(const LinearMachine& m, double I);
// Case ii: T' meets the voltage ellipse (with R_s); the root with the largest i_q.
// Returns false if the torque curve misses the ellipse.
bool voltage_limit(const LinearMachine& m, double omega, double V_max, double T_red, Point& out);
// Zero torque: i_q = 0 and the smallest |i_d| that brings the voltage within V_max.
bool zero_torque(const LinearMachine& m, double omega, double V_max, Point& out);
// The maximum-torque point on the voltage ellipse (MTPV, with R_s).
bool mtpv(const LinearMachine& m, double omega, double V_max, Point& out);
// The current circle meets the voltage ellipse, i_q > 0, largest torque.
bool current_voltage_intersection(const LinearMachine& m, double omega, double V_max, double I, Point& out);

// The largest reduced torque reachable (T' >= 0 side) and the point giving it
// (decision::max_torque on the linear machine).
struct Limit {
    Point point;
    double T_red;
    Region region;  // mtpa (current limit only), mtpv or current_and_voltage_limit
    bool feasible;
};
Limit max_torque(const LinearMachine& m, const OperatingLimits& lim);

// The whole decision for one torque command (either sign, either speed sign): clamp to T_max,
// then MTPA or Case ii (decision.hpp). Fills every field of CurrentCommand (iterations = 0).
class CommandSolver {
public:
    explicit CommandSolver(int pole_pairs);
    CurrentCommand operator()(const LinearMachine& m, double T_ref, const OperatingLimits& lim) const;

private:
    double kT_;  // torque factor 1.5 p
};

// The same with a solver built for the call.
CurrentCommand optimal_current(const LinearMachine& m, int pole_pairs, double T_ref, const OperatingLimits& lim);

}  // namespace ipmsm::linear
