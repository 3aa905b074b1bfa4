// Discrete current regulator in rotor coordinates, written in flux linkage so that saturation
// does not change its dynamics: a two-degree-of-freedom PI on psi = psi(i) from the flux map,
//     u = R_s i + omega J psi(i) + 2 alpha_c (psi(i_ref) - psi(i)) + v,
//     dv/dt = alpha_c^2 (psi(i_ref) - psi(i)) - alpha_c dpsi(i_ref)/dt,
// which makes the flux (and so the current) follow its reference as alpha_c / (s + alpha_c),
// without overshoot, on any map (it is the IMC design of Harnefors et al. with the plant's
// dpsi/dt = u - R i - omega J psi; J rotates by +90 degrees). In discrete time, with the
// one-sample delay compensated, both closed-loop poles sit at 1 - alpha_c h.
//
// One-sample delay, as in a digital drive and in FMI co-simulation: the voltage computed at t_k
// from the currents sampled at t_k is applied over [t_k + h, t_k + 2h]; over [t_k, t_k + h] the
// previous command is being applied, so the regulator acts on the current predicted for t_k + h.
// The voltage is limited to the inverter's linear range u_dc / sqrt 3 (SVPWM), and the integrator
// is corrected by what the limit took away (anti-windup).
#pragma once

#include "machine/magnet_flux.hpp"

namespace ipmsm {

struct RegulatorState {
    double v_d = 0, v_q = 0;                // integrator, V
    double u_d_prev = 0, u_q_prev = 0;      // voltage being applied now, V
    double psi_ref_d = 0, psi_ref_q = 0;    // last reference flux (map at T_magnet_ref), Wb
    bool primed = false;                    // psi_ref_* hold a previous reference
};

struct VoltageCommand {
    double u_d, u_q;  // V
    bool limited;     // the inverter's linear range limited it
};

class CurrentRegulator {
public:
    // bandwidth: closed-loop current bandwidth alpha_c, rad/s.
    CurrentRegulator(double bandwidth, double R_s) : alpha_c_(bandwidth), R_s_(R_s) {}

    VoltageCommand step(double i_d_ref, double i_q_ref, double i_d, double i_q, double omega,
                        double u_dc, double h, const MagnetFlux& flux);

    RegulatorState state;

private:
    double alpha_c_;
    double R_s_;
};

}  // namespace ipmsm
