// Newton's method on the flux map for the exact current-minimising conditions of a saturated
// machine. Each operating condition is two equations in (i_d, i_q), built from three scalar
// fields with gradients and Hessians: reduced torque T' = psi_d i_q - psi_q i_d, squared
// voltage g = v_d^2 + v_q^2 and squared current c = i_d^2 + i_q^2.
//   MTPA for T*:            T' = T*,   grad c x grad T' = 0 (Lagrange: the circle touches the torque curve)
//   voltage limit for T*:   T' = T*,   g = V^2
//   MTPA at the current limit: c = I^2, grad c x grad T' = 0
//   MTPV:                   g = V^2,   grad g x grad T' = 0
//   current & voltage limit: c = I^2,   g = V^2
#pragma once

#include "machine/magnet_flux.hpp"

namespace ipmsm::map_newton {

enum class System { mtpa, voltage_limit, mtpa_at_current, mtpv, current_voltage };

struct Problem {
    System system;
    double omega;  // electrical speed, rad/s
    double R_s;    // Ohm
    double T_red;  // torque target T / (1.5 p), for mtpa and voltage_limit
    double V_max;  // V
    double I_max;  // A
};

struct Result {
    double i_d, i_q;
    int iterations;
    bool converged;
};

// From the seed (i_d, i_q), at most max_iterations steps; converged after a step below
// tolerance_A (Newton converges quadratically: the error left after a step of size d is of the
// order d^2 / (current scale), far below the 1e-3 A default). Steps are limited to max_step_A to keep Newton on the seed's branch.
Result solve(const MagnetFlux& flux, const Problem& problem, double i_d, double i_q, int max_iterations = 12,
             double tolerance_A = 1e-3, double max_step_A = 50.0);

// At a point where the current circle meets the voltage limit: does moving along the circle towards
// more torque (torque_sign +1: more T, -1: less) raise the voltage? Else a local maximum of the
// torque along the circle lies within the voltage limit next to it.
bool voltage_limit_binds_on_circle(const MagnetFlux& flux, double omega, double R_s, double torque_sign, double i_d,
                                   double i_q);

// Is (i_d, i_q) a local maximum of torque_sign T' within |i| <= I_max and |v| <= V_max (first
// order, Karush-Kuhn-Tucker)? The limits met to `active` (relative, on the squares) bind, and
// grad T'' = lambda grad c + mu grad g must hold with lambda, mu >= 0 for them, to `tolerance`
// (relative to the gradients); within both limits, only where grad T' = 0.
bool torque_local_maximum(const MagnetFlux& flux, double omega, double R_s, double torque_sign, double i_d, double i_q,
                          double I_max, double V_max, double active, double tolerance);

// Squared steady-state voltage at a current.
double voltage_sq(const MagnetFlux& flux, double omega, double R_s, double i_d, double i_q);

}  // namespace ipmsm::map_newton
