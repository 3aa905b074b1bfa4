#include "control/current_regulator.hpp"

#include <cmath>

namespace ipmsm {
namespace {

// sin(x) / x, exact to rounding near 0.
double sinc(double x) { return std::abs(x) < 1e-4 ? 1.0 - x * x / 6.0 : std::sin(x) / x; }

}  // namespace

double CurrentRegulator::bandwidth_at(double h) const { return std::min(alpha_c_, kMaxBandwidthTimesStep / h); }

const CurrentRegulator::SampleConstants& CurrentRegulator::constants(double theta, double h) {
    SampleConstants& k = constants_;
    if (theta == k.theta && h == k.h) return k;
    k.theta = theta;
    k.h = h;
    k.cos_theta = std::cos(theta);
    k.sin_theta = std::sin(theta);
    k.cos_half = std::cos(theta / 2);
    k.sin_half = std::sin(theta / 2);
    k.g_abs = sinc(theta / 2);
    k.lambda = std::exp(-bandwidth_at(h) * h);
    return k;
}

const FluxPoint& CurrentRegulator::reference_flux(double i_d_ref, double i_q_ref, const MagnetFlux& flux) {
    ReferenceFlux& r = reference_;
    if (i_d_ref == r.i_d_ref && i_q_ref == r.i_q_ref && flux.shift() == r.shift && &flux.map() == r.map) return r.at;
    r.map = &flux.map();
    r.i_d_ref = i_d_ref;
    r.i_q_ref = i_q_ref;
    r.shift = flux.shift();
    r.at = flux.eval(i_d_ref, i_q_ref);
    return r.at;
}

VoltageCommand CurrentRegulator::step(Dq i_ref, Dq i, double omega, double u_dc, double h, const MagnetFlux& flux) {
    const double theta = omega * h;  // electrical rotation within the sample, rad
    RegulatorState& s = state;
    const double u_lim = linear_range(u_dc);
    auto limit = [u_lim](Dq& u) {  // to u_lim, keeping the angle
        const double mag = u.abs();
        if (!(mag > u_lim)) return false;
        u = (u_lim / mag) * u;
        return true;
    };
    // What the next sample needs of this one: the reference flux and the voltage it applies.
    auto remember = [&s](Dq psi_ref, Dq u) {
        s.psi_ref = psi_ref;
        s.primed = true;
        s.u_prev = u;
    };
    const FluxPoint& fr = reference_flux(i_ref.d, i_ref.q, flux);
    const Dq psi_ref{fr.psi_d, fr.psi_q};
    const Dq r{fr.psi_d - flux.shift(), fr.psi_q};  // at the reference magnet temperature
    if (!(std::abs(theta) < kMaxRotationPerSample)) {
        // Open loop: the reference's steady-state voltage R_s i_ref + j omega psi_ref; the integrator held.
        Dq u = R_s_ * i_ref + omega * psi_ref.j();
        const bool limited = limit(u);
        remember(r, u);
        return {u.d, u.q, limited, true};
    }
    const SampleConstants& k = constants(theta, h);
    const Rotation back{k.cos_theta, -k.sin_theta};     // Phi = exp(-j omega h)
    const Rotation half_back{k.cos_half, -k.sin_half};  // in Gamma = h g
    const Rotation half_ahead = half_back.inverse();    // in g^-1
    const double g_abs = k.g_abs;

    // Gamma x = h g x: the flux change a held voltage x makes over the sample.
    auto gamma = [&](Dq x) { return h * g_abs * half_back(x); };
    // The current change for a flux change, by the incremental inductances at the sample (it
    // only enters the resistive drop R_s i, a few percent of the voltage).
    const FluxPoint f = flux.eval(i.d, i.q);
    const Dq psi{f.psi_d, f.psi_q};
    const double det = f.L_dd * f.L_qq - f.L_dq * f.L_qd;
    auto current_change = [&](Dq dpsi) -> Dq {
        return {(f.L_qq * dpsi.d - f.L_dq * dpsi.q) / det, (-f.L_qd * dpsi.d + f.L_dd * dpsi.q) / det};
    };

    // 1. The flux at t + h under the voltage being applied now, z = Phi psi + Gamma (u_prev -
    //    R_s i_mean), exact but for i_mean: the current's mean over the sample, taken as the mean
    //    of its ends (the end from a first prediction with i_mean = i).
    const Dq rot = back(psi);
    Dq di = current_change(rot + gamma(s.u_prev - R_s_ * i) - psi);
    const Dq z = rot + gamma(s.u_prev - R_s_ * (i + 0.5 * di));
    di = current_change(z - psi);
    const Dq i_p = i + di;  // the current at t + h

    // 2. Flux error, and the reference's own change (taken at the reference magnet temperature,
    //    so that a change of T_magnet, which shifts both fluxes alike, is not a reference step).
    const Dq e = psi_ref - z;
    const double lambda = k.lambda;       // both closed-loop poles
    const double c = (1.0 - lambda) / h;  // -> alpha_c as h -> 0
    if (s.primed) s.v -= c * (r - s.psi_ref);

    // 3. The integrator's input w (V), then the voltage: resistive drop and back-EMF of the
    //    predicted flux, plus g^-1 w. The resistive drop is at the mean current over [t + h,
    //    t + 2h], whose end is where w takes the flux (z + h w).
    const Dq w = 2.0 * c * e + s.v;
    const Dq gw = half_ahead(w / g_abs);
    const Dq ff = R_s_ * (i_p + 0.5 * current_change(h * w)) + omega * z.j();

    // 4. The inverter's linear range (SVPWM): |u| <= u_dc / sqrt 3, keeping the angle.
    Dq u = ff + gw;
    const bool limited = limit(u);

    // 5. Integrator, corrected by what the limit took away, seen at the integrator's input
    //    (w realised = g (u - feedforward)): anti-windup by back-calculation.
    s.v += h * c * c * e;
    if (limited) s.v += half_back(g_abs * (u - ff)) - w;
    remember(r, u);
    return {u.d, u.q, limited, false};
}

}  // namespace ipmsm
