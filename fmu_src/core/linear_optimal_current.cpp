#include "linear_optimal_current.hpp"

#include <algorithm>
#include <cmath>

#include "quartic.hpp"

namespace ipmsm::linear {
namespace {

// Relative slack on the limits, so that a point computed *on* a limit counts as within it.
constexpr double kLimitSlack = 1e-9;

// Below this |L_d - L_q| / max(L_d, L_q) the machine is treated as non-salient (surface PM).
constexpr double kNonSalient = 1e-9;

bool non_salient(const LinearMachine& m) {
    return std::abs(m.L_d - m.L_q) <= kNonSalient * std::max(std::abs(m.L_d), std::abs(m.L_q));
}

// On the torque curve, i_d from i_q: T' = i_q (psi_m + dL i_d).
double i_d_on_torque_curve(const LinearMachine& m, double T_red, double i_q) {
    return (T_red / i_q - m.psi_m) / (m.L_d - m.L_q);
}

// The larger i_d on the voltage ellipse for a given i_q (used for non-salient machines).
bool i_d_on_ellipse(const LinearMachine& m, double omega, double V_max, double i_q, double& i_d) {
    const double a = m.R_s * m.R_s + omega * omega * m.L_d * m.L_d;
    const double e_q = m.R_s * i_q + omega * m.psi_m;  // v_q without the i_d term
    const double b = 2.0 * (-m.R_s * omega * m.L_q * i_q + omega * m.L_d * e_q);
    const double c = omega * omega * m.L_q * m.L_q * i_q * i_q + e_q * e_q - V_max * V_max;
    const RealRoots r = solve_quadratic(a, b, c);
    if (r.count == 0) return false;
    i_d = r.root[r.count - 1];
    return true;
}

}  // namespace

double voltage_sq(const LinearMachine& m, double omega, double i_d, double i_q) {
    const double v_d = m.R_s * i_d - omega * m.L_q * i_q;
    const double v_q = m.R_s * i_q + omega * (m.L_d * i_d + m.psi_m);
    return v_d * v_d + v_q * v_q;
}

double reduced_torque(const LinearMachine& m, double i_d, double i_q) {
    return m.psi_m * i_q + (m.L_d - m.L_q) * i_d * i_q;
}

Point mtpa(const LinearMachine& m, double T_red) {
    if (!(T_red > 0)) return {0.0, 0.0};
    const double dL = m.L_d - m.L_q;
    double i_q = 0;
    if (non_salient(m)) {
        i_q = m.psi_m > 0 ? T_red / m.psi_m : 0.0;
    } else {
        // dL^2 i_q^4 + psi_m T' i_q - T'^2 = 0 has exactly one positive root (psi_m >= 0).
        const double k = 1.0 / (dL * dL);
        const RealRoots r = solve_depressed_quartic(0.0, m.psi_m * T_red * k, -T_red * T_red * k);
        for (int j = 0; j < r.count; ++j) i_q = std::max(i_q, r.root[j]);
    }
    if (!(i_q > 0)) return {0.0, 0.0};  // no torque producible (psi_m = 0 and dL = 0)
    // The MTPA condition psi_m i_d + dL (i_d^2 - i_q^2) = 0, solved for i_d without
    // cancellation (and without dividing by dL, so non-salient machines give i_d = 0).
    const double s = std::sqrt(m.psi_m * m.psi_m + 4.0 * dL * dL * i_q * i_q);
    const double i_d = 2.0 * dL * i_q * i_q / (m.psi_m + s);
    return {i_d, i_q};
}

Point mtpa_at_current(const LinearMachine& m, double I) {
    const double dL = m.L_d - m.L_q;
    const double s = std::sqrt(m.psi_m * m.psi_m + 8.0 * dL * dL * I * I);
    const double denom = m.psi_m + s;
    const double i_d = denom > 0 ? 2.0 * dL * I * I / denom : 0.0;
    return {i_d, std::sqrt(std::max(0.0, I * I - i_d * i_d))};
}

bool voltage_limit(const LinearMachine& m, double omega, double V_max, double T_red, Point& out) {
    const double R = m.R_s, w = omega, dL = m.L_d - m.L_q, psi = m.psi_m;
    if (non_salient(m)) {
        if (!(psi > 0)) return false;
        const double i_q = T_red / psi;
        double i_d;
        if (!i_d_on_ellipse(m, omega, V_max, i_q, i_d)) return false;
        out = {i_d, i_q};
        return true;
    }
    const double zq = R * R + w * w * m.L_q * m.L_q;
    const double a4 = dL * dL * zq;
    const double a2 = psi * psi * zq + 2.0 * R * w * dL * dL * T_red - V_max * V_max * dL * dL;
    const double a1 = -2.0 * psi * T_red * (R * R + w * w * m.L_d * m.L_q);
    const double a0 = T_red * T_red * (R * R + w * w * m.L_d * m.L_d);
    const RealRoots r = solve_depressed_quartic(a2 / a4, a1 / a4, a0 / a4);
    // Every intersection is on the ellipse; the current along the torque curve has its minimum
    // at the MTPA point (outside the ellipse here), so the best is the intersection with the
    // least current. (For the usual geometry that is the root with the largest i_q.)
    double best = INFINITY;
    for (int k = 0; k < r.count; ++k) {
        const double i_q = r.root[k];
        if (!(i_q > 0)) continue;
        const double i_d = i_d_on_torque_curve(m, T_red, i_q);
        const double I2 = i_d * i_d + i_q * i_q;
        if (I2 < best) {
            best = I2;
            out = {i_d, i_q};
        }
    }
    return best < INFINITY;
}

bool voltage_limit_is_optimal(const LinearMachine& m, double omega, Point p) {
    const double dL = m.L_d - m.L_q;
    // Tangent of the torque curve t = (-dT'/di_q, dT'/di_d); rates of |i|^2 and |v|^2 along it.
    const double t_d = -(m.psi_m + dL * p.i_d), t_q = dL * p.i_q;
    const double v_d = m.R_s * p.i_d - omega * m.L_q * p.i_q;
    const double v_q = m.R_s * p.i_q + omega * (m.L_d * p.i_d + m.psi_m);
    const double g_d = v_d * m.R_s + v_q * omega * m.L_d;   // half the gradient of |v|^2
    const double g_q = -v_d * omega * m.L_q + v_q * m.R_s;
    const double dc = p.i_d * t_d + p.i_q * t_q, dg = g_d * t_d + g_q * t_q;
    return dc * dg <= 0.0;
}

bool zero_torque(const LinearMachine& m, double omega, double V_max, Point& out) {
    if (voltage_sq(m, omega, 0.0, 0.0) <= V_max * V_max) {
        out = {0.0, 0.0};
        return true;
    }
    double i_d;
    if (!i_d_on_ellipse(m, omega, V_max, 0.0, i_d)) return false;
    out = {i_d, 0.0};
    return true;
}

bool mtpv(const LinearMachine& m, double omega, double V_max, Point& out) {
    // On the ellipse, v = V (cos th, sin th) and i = M^-1 (v - (0, omega psi_m)) is affine in
    // (cos th, sin th); T'(th) is then a quadratic form whose stationary points are the roots
    // of a quartic in t = tan(th / 2).
    const double R = m.R_s, w = omega, psi = m.psi_m, dL = m.L_d - m.L_q;
    const double det = R * R + w * w * m.L_d * m.L_q;
    if (!(det > 0)) return false;
    const double ad = -w * w * m.L_q * psi / det, bd = R * V_max / det, gd = w * m.L_q * V_max / det;
    const double aq = -R * w * psi / det, bq = -w * m.L_d * V_max / det, gq = R * V_max / det;
    const double a = dL * bd * bq, b = dL * gd * gq, k = dL * (bd * gq + gd * bq);
    const double d = psi * bq + dL * (ad * bq + bd * aq);
    const double e = psi * gq + dL * (ad * gq + gd * aq);
    const RealRoots r = solve_quartic(k - e, -4.0 * (b - a) - 2.0 * d, -6.0 * k, 4.0 * (b - a) - 2.0 * d, k + e);
    // Candidates: the stationary points, and th = pi (t = infinity), where the quartic's degree drops.
    double best = -INFINITY;
    auto consider = [&](double c, double s) {
        const Point p{ad + bd * c + gd * s, aq + bq * c + gq * s};
        const double T = reduced_torque(m, p.i_d, p.i_q);
        if (T > best) {
            best = T;
            out = p;
        }
    };
    for (int j = 0; j < r.count; ++j) {
        const double t = r.root[j], t2 = t * t;
        consider((1.0 - t2) / (1.0 + t2), 2.0 * t / (1.0 + t2));
    }
    consider(-1.0, 0.0);
    return best > -INFINITY;
}

bool current_voltage_intersection(const LinearMachine& m, double omega, double V_max, double I,
                                  Point& out) {
    // On the circle, i = I (cos ph, sin ph): |v|^2 = V^2 is a quadratic form in (cos, sin),
    // a quartic in t = tan(ph / 2); i_q > 0 <=> t > 0.
    const double R = m.R_s, w = omega, psi = m.psi_m, dL = m.L_d - m.L_q;
    const double A = I * I * w * w * m.L_d * m.L_d, B = I * I * w * w * m.L_q * m.L_q;
    const double C = 2.0 * I * I * R * w * dL, D = 2.0 * I * w * w * psi * m.L_d;
    const double E = 2.0 * I * w * R * psi, F = I * I * R * R + w * w * psi * psi - V_max * V_max;
    const RealRoots r = solve_quartic(A - D + F, 2.0 * (E - C), 2.0 * (F - A) + 4.0 * B, 2.0 * (C + E), A + D + F);
    double best = -INFINITY;
    for (int j = 0; j < r.count; ++j) {
        const double t = r.root[j], t2 = t * t;
        if (!(t > 0)) continue;
        const Point p{I * (1.0 - t2) / (1.0 + t2), I * 2.0 * t / (1.0 + t2)};
        const double T = reduced_torque(m, p.i_d, p.i_q);
        if (T > best) {
            best = T;
            out = p;
        }
    }
    return best > -INFINITY;
}

Limit max_torque(const LinearMachine& m, const OperatingLimits& lim) {
    const double V2 = lim.V_max * lim.V_max * (1.0 + kLimitSlack);
    const Point p1 = mtpa_at_current(m, lim.I_max);
    if (voltage_sq(m, lim.omega, p1.i_d, p1.i_q) <= V2)
        return {p1, reduced_torque(m, p1.i_d, p1.i_q), Region::mtpa, true};
    Point p2;
    if (mtpv(m, lim.omega, lim.V_max, p2) &&
        p2.i_d * p2.i_d + p2.i_q * p2.i_q <= lim.I_max * lim.I_max * (1.0 + kLimitSlack)) {
        const double T = reduced_torque(m, p2.i_d, p2.i_q);
        if (T >= 0) return {p2, T, Region::mtpv, true};
    }
    Point p3;
    if (current_voltage_intersection(m, lim.omega, lim.V_max, lim.I_max, p3)) {
        const double T = reduced_torque(m, p3.i_d, p3.i_q);
        if (T >= 0) return {p3, T, Region::current_and_voltage_limit, true};
    }
    // Above the maximum speed: no current within I_max brings the voltage within V_max.
    return {{-lim.I_max, 0.0}, 0.0, Region::zero_torque, false};
}

CurrentCommand optimal_current(const LinearMachine& m, int pole_pairs, double T_ref,
                               const OperatingLimits& lim) {
    // Mirror negative torque onto positive: (T, omega, i_q) -> (-T, -omega, -i_q).
    const double sign = T_ref < 0 ? -1.0 : 1.0;
    const OperatingLimits L{sign * lim.omega, lim.V_max, lim.I_max};
    const double kT = torque_factor(pole_pairs);
    const double T_red = std::abs(T_ref) / kT;

    CurrentCommand cmd;
    const Limit top = max_torque(m, L);
    cmd.torque_max = top.T_red * kT;
    Point p{0.0, 0.0};
    if (!top.feasible) {
        cmd.feasible = false;
        cmd.region = Region::zero_torque;
        p = top.point;
    } else if (T_red >= top.T_red) {
        p = top.point;
        cmd.region = top.region;
    } else if (T_red == 0.0) {
        if (!zero_torque(m, L.omega, L.V_max, p)) p = top.point;
        cmd.region = Region::zero_torque;
    } else if (top.region == Region::mtpa) {
        // Below the base speed for this torque side: MTPA first (seed Case i).
        p = mtpa(m, T_red);
        cmd.region = Region::mtpa;
        if (voltage_sq(m, L.omega, p.i_d, p.i_q) > L.V_max * L.V_max * (1.0 + kLimitSlack)) {
            cmd.region = Region::voltage_limit;
            if (!voltage_limit(m, L.omega, L.V_max, T_red, p)) {
                p = top.point;
                cmd.region = top.region;
            }
        }
    } else {
        // Field weakening: the seed's order, Case ii first, then the a-priori test says whether
        // MTPA is needed at all, which saves a quartic whenever the voltage limit is active.
        cmd.region = Region::voltage_limit;
        if (!voltage_limit(m, L.omega, L.V_max, T_red, p)) {
            p = top.point;  // only at the edge of reach
            cmd.region = top.region;
        } else if (!voltage_limit_is_optimal(m, L.omega, p)) {
            const Point q = mtpa(m, T_red);
            if (voltage_sq(m, L.omega, q.i_d, q.i_q) <= L.V_max * L.V_max * (1.0 + kLimitSlack)) {
                p = q;
                cmd.region = Region::mtpa;
            }
        }
    }
    cmd.i_d = p.i_d;
    cmd.i_q = sign * p.i_q;
    cmd.torque = kT * reduced_torque(m, cmd.i_d, cmd.i_q);
    return cmd;
}

}  // namespace ipmsm::linear
