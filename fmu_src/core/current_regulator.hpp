// Discrete PI current regulator in rotor coordinates: K_p = alpha_c L (L: the incremental inductance
// matrix from the flux map), K_i = alpha_i K_p, with the resistive drop and the back-EMF fed
// forward through the flux map (so the integrator only corrects model errors), the one-sample computation delay of a
// digital drive compensated by predicting the current at the instant the new voltage takes
// effect, and the voltage limited to the inverter's linear range u_dc / sqrt(3) with
// anti-windup (the integrator sees the error the limited voltage can realise).
//
// Timing, as in a digital drive and in FMI co-simulation: the voltage computed at t_k from the
// currents sampled at t_k is applied over [t_k + h, t_k + 2h]; over [t_k, t_k + h] the previous
// command is being applied.
#pragma once

#include "magnet_flux.hpp"

namespace ipmsm {

struct RegulatorState {
    double u_i_d = 0, u_i_q = 0;    // integrator, V
    double u_d_prev = 0, u_q_prev = 0;  // voltage being applied now, V
};

struct VoltageCommand {
    double u_d, u_q;  // V
    bool limited;     // the inverter's linear range limited it
};

class CurrentRegulator {
public:
    // bandwidth: closed-loop current bandwidth alpha_c, rad/s.
    CurrentRegulator(double bandwidth, double R_s) : alpha_c_(bandwidth), R_s_(R_s) {}

    // Integral gain relative to the bandwidth: alpha_i = alpha_c / 5 keeps the PI's zero well
    // below the closed-loop bandwidth (little overshoot) while removing steady-state error.
    static constexpr double integral_ratio = 0.2;

    VoltageCommand step(double i_d_ref, double i_q_ref, double i_d, double i_q, double omega,
                        double u_dc, double h, const MagnetFlux& flux);

    RegulatorState state;

private:
    double alpha_c_;
    double R_s_;
};

}  // namespace ipmsm
