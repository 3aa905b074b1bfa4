#include "current_regulator.hpp"

#include <cmath>

namespace ipmsm {

VoltageCommand CurrentRegulator::step(double i_d_ref, double i_q_ref, double i_d, double i_q, double omega,
                                      double u_dc, double h, const MagnetFlux& flux) {
    RegulatorState& s = state;
    // 1. Predict the current at t + h under the voltage being applied now (flux dynamics
    //    dpsi/dt = u - R i - omega J psi, mapped to current by the incremental inductances).
    const FluxPoint f = flux.eval(i_d, i_q);
    const double dpsi_d = h * (s.u_d_prev - R_s_ * i_d + omega * f.psi_q);
    const double dpsi_q = h * (s.u_q_prev - R_s_ * i_q - omega * f.psi_d);
    const double det = f.L_dd * f.L_qq - f.L_dq * f.L_qd;
    const double i_d_p = i_d + (f.L_qq * dpsi_d - f.L_dq * dpsi_q) / det;
    const double i_q_p = i_q + (-f.L_qd * dpsi_d + f.L_dd * dpsi_q) / det;

    // 2. PI on the predicted error, K_p = alpha_c L (the incremental inductance matrix there),
    //    plus the steady-state voltage R i_ref + omega J psi from the flux map.
    const FluxPoint fp = flux.eval(i_d_p, i_q_p);
    const double e_d = i_d_ref - i_d_p, e_q = i_q_ref - i_q_p;
    const double p_d = alpha_c_ * (fp.L_dd * e_d + fp.L_dq * e_q);  // K_p e
    const double p_q = alpha_c_ * (fp.L_qd * e_d + fp.L_qq * e_q);
    const double u_d = p_d + s.u_i_d + R_s_ * i_d_ref - omega * fp.psi_q;
    const double u_q = p_q + s.u_i_q + R_s_ * i_q_ref + omega * fp.psi_d;

    // 3. The inverter's linear range (SVPWM): |u| <= u_dc / sqrt 3, keeping the angle.
    const double u_lim = u_dc / std::sqrt(3.0);
    const double mag = std::hypot(u_d, u_q);
    const bool limited = mag > u_lim;
    const double scale = limited ? u_lim / mag : 1.0;
    const double u_d_out = u_d * scale, u_q_out = u_q * scale;

    // 4. Anti-windup: integrate K_i e_r with the error the limited voltage realises,
    //    e_r = e + K_p^-1 (u_out - u), i.e. K_i e_r = alpha_i (K_p e + u_out - u).
    const double alpha_i = integral_ratio * alpha_c_;
    s.u_i_d += h * alpha_i * (p_d + u_d_out - u_d);
    s.u_i_q += h * alpha_i * (p_q + u_q_out - u_q);
    s.u_d_prev = u_d_out;
    s.u_q_prev = u_q_out;
    return {u_d_out, u_q_out, limited};
}

}  // namespace ipmsm
