#include "control/current_regulator.hpp"

#include <cmath>

namespace ipmsm {
namespace {

// (a + j b) times exp(j angle), with its cosine and sine.
struct Rotation {
    double c, s;
    void apply(double& a, double& b) const {
        const double a2 = a * c - b * s;
        b = a * s + b * c;
        a = a2;
    }
};

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

VoltageCommand CurrentRegulator::step(double i_d_ref, double i_q_ref, double i_d, double i_q, double omega, double u_dc,
                                      double h, const MagnetFlux& flux) {
    const double theta = omega * h;  // electrical rotation within the sample, rad
    RegulatorState& s = state;
    const double u_lim = linear_range(u_dc);
    auto limit = [u_lim](double& u_d, double& u_q) {  // to u_lim, keeping the angle
        const double mag = std::hypot(u_d, u_q);
        if (!(mag > u_lim)) return false;
        u_d *= u_lim / mag;
        u_q *= u_lim / mag;
        return true;
    };
    // What the next sample needs of this one: the reference flux and the voltage it applies.
    auto remember = [&s](double psi_ref_d, double psi_ref_q, double u_d, double u_q) {
        s.psi_ref_d = psi_ref_d;
        s.psi_ref_q = psi_ref_q;
        s.primed = true;
        s.u_d_prev = u_d;
        s.u_q_prev = u_q;
    };
    const FluxPoint& fr = reference_flux(i_d_ref, i_q_ref, flux);
    const double r_d = fr.psi_d - flux.shift(), r_q = fr.psi_q;  // at the reference magnet temperature
    if (!(std::abs(theta) < kMaxRotationPerSample)) {
        // Open loop: the reference's steady-state voltage; the integrator held.
        double u_d = R_s_ * i_d_ref - omega * fr.psi_q, u_q = R_s_ * i_q_ref + omega * fr.psi_d;
        const bool limited = limit(u_d, u_q);
        remember(r_d, r_q, u_d, u_q);
        return {u_d, u_q, limited, true};
    }
    const SampleConstants& k = constants(theta, h);
    const Rotation back{k.cos_theta, -k.sin_theta};        // Phi = exp(-j omega h)
    const Rotation half_back{k.cos_half, -k.sin_half};     // in Gamma = h g
    const Rotation half_ahead{half_back.c, -half_back.s};  // in g^-1
    const double g_abs = k.g_abs;

    // Gamma (a + j b) = h g (a + j b): the flux change a held voltage a + j b makes over the sample.
    auto gamma = [&](double a, double b, double& out_d, double& out_q) {
        half_back.apply(a, b);
        out_d = h * g_abs * a;
        out_q = h * g_abs * b;
    };
    // The current change for a flux change, by the incremental inductances at the sample (it
    // only enters the resistive drop R_s i, a few percent of the voltage).
    const FluxPoint f = flux.eval(i_d, i_q);
    const double det = f.L_dd * f.L_qq - f.L_dq * f.L_qd;
    auto current_change = [&](double dpsi_d, double dpsi_q, double& di_d, double& di_q) {
        di_d = (f.L_qq * dpsi_d - f.L_dq * dpsi_q) / det;
        di_q = (-f.L_qd * dpsi_d + f.L_dd * dpsi_q) / det;
    };

    // 1. The flux at t + h under the voltage being applied now, z = Phi psi + Gamma (u_prev -
    //    R_s i_mean), exact but for i_mean: the current's mean over the sample, taken as the mean
    //    of its ends (the end from a first prediction with i_mean = i).
    double rot_d = f.psi_d, rot_q = f.psi_q;
    back.apply(rot_d, rot_q);
    double dz_d, dz_q, di_d, di_q;
    gamma(s.u_d_prev - R_s_ * i_d, s.u_q_prev - R_s_ * i_q, dz_d, dz_q);
    current_change(rot_d + dz_d - f.psi_d, rot_q + dz_q - f.psi_q, di_d, di_q);
    gamma(s.u_d_prev - R_s_ * (i_d + 0.5 * di_d), s.u_q_prev - R_s_ * (i_q + 0.5 * di_q), dz_d, dz_q);
    const double z_d = rot_d + dz_d, z_q = rot_q + dz_q;
    current_change(z_d - f.psi_d, z_q - f.psi_q, di_d, di_q);
    const double i_d_p = i_d + di_d, i_q_p = i_q + di_q;  // the current at t + h

    // 2. Flux error, and the reference's own change (taken at the reference magnet temperature,
    //    so that a change of T_magnet, which shifts both fluxes alike, is not a reference step).
    const double e_d = fr.psi_d - z_d, e_q = fr.psi_q - z_q;
    const double lambda = k.lambda;       // both closed-loop poles
    const double c = (1.0 - lambda) / h;  // -> alpha_c as h -> 0
    if (s.primed) {
        s.v_d -= c * (r_d - s.psi_ref_d);
        s.v_q -= c * (r_q - s.psi_ref_q);
    }

    // 3. The integrator's input w (V), then the voltage: resistive drop and back-EMF of the
    //    predicted flux, plus g^-1 w.
    const double w_d = 2.0 * c * e_d + s.v_d, w_q = 2.0 * c * e_q + s.v_q;
    double gw_d = w_d / g_abs, gw_q = w_q / g_abs;
    half_ahead.apply(gw_d, gw_q);
    // The resistive drop at the mean current over [t + h, t + 2h], whose end is where w takes
    // the flux (z + h w).
    double dn_d, dn_q;
    current_change(h * w_d, h * w_q, dn_d, dn_q);
    const double ff_d = R_s_ * (i_d_p + 0.5 * dn_d) - omega * z_q, ff_q = R_s_ * (i_q_p + 0.5 * dn_q) + omega * z_d;
    const double u_d = ff_d + gw_d, u_q = ff_q + gw_q;

    // 4. The inverter's linear range (SVPWM): |u| <= u_dc / sqrt 3, keeping the angle.
    double u_d_out = u_d, u_q_out = u_q;
    const bool limited = limit(u_d_out, u_q_out);

    // 5. Integrator, corrected by what the limit took away, seen at the integrator's input
    //    (w realised = g (u_out - feedforward)): anti-windup by back-calculation.
    s.v_d += h * c * c * e_d;
    s.v_q += h * c * c * e_q;
    if (limited) {
        double wr_d = (u_d_out - ff_d) * g_abs, wr_q = (u_q_out - ff_q) * g_abs;
        half_back.apply(wr_d, wr_q);
        s.v_d += wr_d - w_d;
        s.v_q += wr_q - w_q;
    }
    remember(r_d, r_q, u_d_out, u_q_out);
    return {u_d_out, u_q_out, limited, false};
}

}  // namespace ipmsm
