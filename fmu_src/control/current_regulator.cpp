#include "control/current_regulator.hpp"

#include <cmath>

namespace ipmsm {

VoltageCommand CurrentRegulator::step(double i_d_ref, double i_q_ref, double i_d, double i_q, double omega,
                                      double u_dc, double h, const MagnetFlux& flux) {
    RegulatorState& s = state;
    // 1. Predict the current at t + h under the voltage being applied now (dpsi/dt from the
    //    model, mapped to current by the incremental inductances at the sample).
    const FluxPoint f = flux.eval(i_d, i_q);
    const double dpsi_d = h * (s.u_d_prev - R_s_ * i_d + omega * f.psi_q);
    const double dpsi_q = h * (s.u_q_prev - R_s_ * i_q - omega * f.psi_d);
    const double det = f.L_dd * f.L_qq - f.L_dq * f.L_qd;
    const double i_d_p = i_d + (f.L_qq * dpsi_d - f.L_dq * dpsi_q) / det;
    const double i_q_p = i_q + (-f.L_qd * dpsi_d + f.L_dd * dpsi_q) / det;

    // 2. Flux error, and the reference's own change (taken at the reference magnet temperature,
    //    so that a change of T_magnet, which shifts both fluxes alike, is not a reference step).
    const FluxPoint fp = flux.eval(i_d_p, i_q_p);
    const FluxPoint fr = flux.eval(i_d_ref, i_q_ref);
    const double e_d = fr.psi_d - fp.psi_d, e_q = fr.psi_q - fp.psi_q;
    const double r_d = fr.psi_d - flux.shift(), r_q = fr.psi_q;
    if (s.primed) {
        s.v_d -= alpha_c_ * (r_d - s.psi_ref_d);
        s.v_q -= alpha_c_ * (r_q - s.psi_ref_q);
    }
    s.psi_ref_d = r_d;
    s.psi_ref_q = r_q;
    s.primed = true;

    // 3. Voltage: resistive drop and back-EMF from the map, plus the 2DOF PI.
    const double u_d = R_s_ * i_d_p - omega * fp.psi_q + 2.0 * alpha_c_ * e_d + s.v_d;
    const double u_q = R_s_ * i_q_p + omega * fp.psi_d + 2.0 * alpha_c_ * e_q + s.v_q;

    // 4. The inverter's linear range (SVPWM): |u| <= u_dc / sqrt 3, keeping the angle.
    const double u_lim = u_dc / std::sqrt(3.0);
    const double mag = std::hypot(u_d, u_q);
    const bool limited = mag > u_lim;
    const double scale = limited ? u_lim / mag : 1.0;
    const double u_d_out = u_d * scale, u_q_out = u_q * scale;

    // 5. Integrator, corrected by what the limit took away (anti-windup by back-calculation).
    s.v_d += h * alpha_c_ * alpha_c_ * e_d + (u_d_out - u_d);
    s.v_q += h * alpha_c_ * alpha_c_ * e_q + (u_q_out - u_q);
    s.u_d_prev = u_d_out;
    s.u_q_prev = u_q_out;
    return {u_d_out, u_q_out, limited};
}

}  // namespace ipmsm
