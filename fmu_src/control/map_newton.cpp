#include "control/map_newton.hpp"

#include <cmath>
#include <type_traits>

namespace ipmsm::map_newton {
namespace {

// A scalar field's value, gradient and Hessian at one point.
struct Field {
    double v, d, q, dd, dq, qq;
};

struct Fields {
    Field T, g, c;
};

// The three fields at one point. The optimality tests need only values and gradients: then
// without Hessians, from the map's eval instead of eval2 (a quarter of its cost).
template <bool with_hessians = true>
Fields fields_at(const MagnetFlux& flux, double w, double R, double i_d, double i_q) {
    std::conditional_t<with_hessians, FluxPoint2, FluxPoint> f;
    if constexpr (with_hessians)
        f = flux.eval2(i_d, i_q);
    else
        f = flux.eval(i_d, i_q);
    Fields F{};
    // T' = psi_d i_q - psi_q i_d
    F.T.v = f.psi_d * i_q - f.psi_q * i_d;
    F.T.d = f.L_dd * i_q - f.L_qd * i_d - f.psi_q;
    F.T.q = f.L_dq * i_q + f.psi_d - f.L_qq * i_d;
    if constexpr (with_hessians) {
        F.T.dd = f.psi_d_dd * i_q - f.psi_q_dd * i_d - 2.0 * f.L_qd;
        F.T.dq = f.psi_d_dq * i_q + f.L_dd - f.psi_q_dq * i_d - f.L_qq;
        F.T.qq = f.psi_d_qq * i_q + 2.0 * f.L_dq - f.psi_q_qq * i_d;
    }
    // v_d = R i_d - w psi_q, v_q = R i_q + w psi_d; g = |v|^2
    const double vd = R * i_d - w * f.psi_q, vq = R * i_q + w * f.psi_d;
    const double j00 = R - w * f.L_qd, j01 = -w * f.L_qq;  // d v_d / d(i_d, i_q)
    const double j10 = w * f.L_dd, j11 = R + w * f.L_dq;   // d v_q / d(i_d, i_q)
    F.g.v = vd * vd + vq * vq;
    F.g.d = 2.0 * (vd * j00 + vq * j10);
    F.g.q = 2.0 * (vd * j01 + vq * j11);
    if constexpr (with_hessians) {
        F.g.dd = 2.0 * (j00 * j00 + j10 * j10 + w * (vq * f.psi_d_dd - vd * f.psi_q_dd));
        F.g.dq = 2.0 * (j00 * j01 + j10 * j11 + w * (vq * f.psi_d_dq - vd * f.psi_q_dq));
        F.g.qq = 2.0 * (j01 * j01 + j11 * j11 + w * (vq * f.psi_d_qq - vd * f.psi_q_qq));
    }
    F.c = {i_d * i_d + i_q * i_q, 2.0 * i_d, 2.0 * i_q, 2.0, 0.0, 2.0};
    return F;
}

Fields gradients_at(const MagnetFlux& flux, double w, double R, double i_d, double i_q) {
    return fields_at<false>(flux, w, R, i_d, i_q);
}

// The z component of a x b.
double cross(double a_d, double a_q, double b_d, double b_q) { return a_d * b_q - a_q * b_d; }

// One equation and its gradient.
struct Eq {
    double F, Fd, Fq;
};

Eq level(const Field& f, double target) { return {f.v - target, f.d, f.q}; }

// grad a x grad b = 0: the level curves of a and b touch.
Eq tangency(const Field& a, const Field& b) {
    return {a.d * b.q - a.q * b.d,  //
            a.dd * b.q + a.d * b.dq - a.dq * b.d - a.q * b.dd, a.dq * b.q + a.d * b.qq - a.qq * b.d - a.q * b.dq};
}

void equations(const Problem& P, const Fields& F, Eq& e1, Eq& e2) {
    const double V2 = P.V_max * P.V_max, I2 = P.I_max * P.I_max;
    switch (P.system) {
        case System::mtpa:
            e1 = level(F.T, P.T_red);
            e2 = tangency(F.c, F.T);
            break;
        case System::voltage_limit:
            e1 = level(F.T, P.T_red);
            e2 = level(F.g, V2);
            break;
        case System::mtpa_at_current:
            e1 = level(F.c, I2);
            e2 = tangency(F.c, F.T);
            break;
        case System::mtpv:
            e1 = level(F.g, V2);
            e2 = tangency(F.g, F.T);
            break;
        case System::current_voltage:
            e1 = level(F.c, I2);
            e2 = level(F.g, V2);
            break;
    }
}

}  // namespace

double voltage_sq(const MagnetFlux& flux, double omega, double R_s, double i_d, double i_q) {
    const FluxPoint f = flux.eval(i_d, i_q);
    const double vd = R_s * i_d - omega * f.psi_q, vq = R_s * i_q + omega * f.psi_d;
    return vd * vd + vq * vq;
}

bool voltage_limit_binds_on_circle(const MagnetFlux& flux, double omega, double R_s, double torque_sign, double i_d,
                                   double i_q) {
    const Fields F = gradients_at(flux, omega, R_s, i_d, i_q);
    // Maximising T'' = torque_sign T' with both limits active (KKT): grad T'' = lambda grad c +
    // mu grad g. Crossing with grad c isolates mu: grad c x grad T'' = mu (grad c x grad g).
    // mu >= 0: along the circle, the way to more torque raises the voltage.
    const double mu_sign =
        cross(F.c.d, F.c.q, torque_sign * F.T.d, torque_sign * F.T.q) * cross(F.c.d, F.c.q, F.g.d, F.g.q);
    return mu_sign >= 0.0;
}

bool torque_local_maximum(const MagnetFlux& flux, double omega, double R_s, double torque_sign, double i_d, double i_q,
                          double I_max, double V_max, double active, double tolerance) {
    const Fields F = gradients_at(flux, omega, R_s, i_d, i_q);
    const double Td = torque_sign * F.T.d, Tq = torque_sign * F.T.q;
    // Not std::hypot (see solve()): gradients of currents and voltages never come near overflow.
    auto norm = [](double x, double y) { return std::sqrt(x * x + y * y); };
    const double T_norm = norm(Td, Tq), c_norm = norm(F.c.d, F.c.q), g_norm = norm(F.g.d, F.g.q);
    const bool on_current = F.c.v >= I_max * I_max * (1.0 - active);
    const bool on_voltage = F.g.v >= V_max * V_max * (1.0 - active);
    // grad T'' = lambda grad c + mu grad g: crossing with grad g isolates lambda, with grad c mu.
    if (on_current && on_voltage) {
        const double det = cross(F.c.d, F.c.q, F.g.d, F.g.q);
        if (det == 0.0) return true;
        const double lambda = cross(Td, Tq, F.g.d, F.g.q) / det, mu = cross(F.c.d, F.c.q, Td, Tq) / det;
        return lambda * c_norm >= -tolerance * T_norm && mu * g_norm >= -tolerance * T_norm;
    }
    if (on_voltage) return Td * F.g.d + Tq * F.g.q >= -tolerance * T_norm * g_norm;
    if (on_current) return Td * F.c.d + Tq * F.c.q >= -tolerance * T_norm * c_norm;
    return T_norm == 0.0;  // within both limits: more torque along its gradient
}

Result solve(const MagnetFlux& flux, const Problem& P, double i_d, double i_q, int max_iterations, double tolerance_A,
             double max_step_A) {
    for (int k = 1; k <= max_iterations; ++k) {
        const Fields F = fields_at(flux, P.omega, P.R_s, i_d, i_q);
        Eq e1{}, e2{};
        equations(P, F, e1, e2);
        const double det = e1.Fd * e2.Fq - e1.Fq * e2.Fd;
        if (!std::isfinite(det) || det == 0.0) return {i_d, i_q, k, false};
        double dd = -(e2.Fq * e1.F - e1.Fq * e2.F) / det;
        double dq = -(-e2.Fd * e1.F + e1.Fd * e2.F) / det;
        // Not std::hypot: its overflow-safe scaling took some 15 % of recursion 2's time, and
        // current steps never come near overflow.
        const double step = std::sqrt(dd * dd + dq * dq);
        if (!std::isfinite(step)) return {i_d, i_q, k, false};
        if (step > max_step_A) {
            dd *= max_step_A / step;
            dq *= max_step_A / step;
        }
        i_d += dd;
        i_q += dq;
        if (step < tolerance_A) return {i_d, i_q, k, true};
    }
    return {i_d, i_q, max_iterations, false};
}

}  // namespace ipmsm::map_newton
