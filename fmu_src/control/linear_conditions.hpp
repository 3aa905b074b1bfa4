// The linear machine's optimality conditions, each as one quartic c[0] x^4 + ... + c[4] = 0 and
// the rule that reads its point from the real roots (used by linear_optimal_current.cpp only).
// The roots come unpolished from Ferrari (centred_quartic_roots); the rule chooses among them,
// then polishes only the chosen root on c. All for the T' >= 0 side
// (linear_optimal_current.hpp) and a salient machine (L_d != L_q).
#pragma once

#include <cmath>

#include "control/linear_optimal_current.hpp"
#include "numerics/quartic.hpp"

namespace ipmsm::linear::conditions {

inline RealRoots roots_of(const double (&c)[5]) { return centred_quartic_roots(c[0], c[1], c[2], c[3], c[4]); }

// Case i (MTPA) for a salient machine: dL^2 i_q^4 + psi_m T' i_q - T'^2 = 0, monic; exactly one
// positive root (psi_m >= 0, T' > 0).
struct MtpaQuartic {
    MtpaQuartic(const LinearMachine& m, double T_red) : m(m) {
        const double dL = m.L_d - m.L_q, k = 1.0 / (dL * dL);
        c[3] = m.psi_m * T_red * k;
        c[4] = -T_red * T_red * k;
    }
    bool point(const RealRoots& r, Point& out) const {
        double i_q = 0;
        for (int j = 0; j < r.count; ++j) i_q = std::max(i_q, r.root[j]);
        if (!(i_q > 0)) return false;
        // The MTPA condition psi_m i_d + dL (i_d^2 - i_q^2) = 0, solved for i_d without
        // cancellation (and without dividing by dL).
        const double dL = m.L_d - m.L_q;
        auto at = [&](double y) {
            const double s = std::sqrt(m.psi_m * m.psi_m + 4.0 * dL * dL * y * y);
            return Point{2.0 * dL * y * y / (m.psi_m + s), y};
        };
        out = at(newton_step(c, i_q).root());
        return true;
    }
    const LinearMachine& m;
    double c[5] = {1.0, 0.0, 0.0, 0.0, 0.0};
};

// Case ii for a salient machine: the torque curve T' meets the voltage ellipse (with R_s), a
// depressed quartic in i_q (MATH.md), monic.
struct VoltageLimitQuartic {
    VoltageLimitQuartic(const LinearMachine& m, double omega, double V_max, double T_red)
        : m(m), T_red(T_red), inv_dL(1.0 / (m.L_d - m.L_q)) {
        const double R = m.R_s, w = omega, dL = m.L_d - m.L_q, psi = m.psi_m;
        const double zq = R * R + w * w * m.L_q * m.L_q;
        const double inv_a4 = 1.0 / (dL * dL * zq);
        c[2] = (psi * psi * zq + 2.0 * R * w * dL * dL * T_red - V_max * V_max * dL * dL) * inv_a4;
        c[3] = -2.0 * psi * T_red * (R * R + w * w * m.L_d * m.L_q) * inv_a4;
        c[4] = T_red * T_red * (R * R + w * w * m.L_d * m.L_d) * inv_a4;
    }
    Point at(double i_q) const { return {(T_red / i_q - m.psi_m) * inv_dL, i_q}; }
    bool point(const RealRoots& r, Point& out) const {
        // Every intersection is on the ellipse; the current along the torque curve has its minimum
        // at the MTPA point (outside the ellipse here), so the best is the intersection with the
        // least current. (For the usual geometry that is the root with the largest i_q.)
        int best = -1;
        double best_I2 = INFINITY;
        for (int k = 0; k < r.count; ++k) {
            if (!(r.root[k] > 0)) continue;
            const Point p = at(r.root[k]);
            const double I2 = p.i_d * p.i_d + p.i_q * p.i_q;
            if (I2 < best_I2) best_I2 = I2, best = k;
        }
        if (best < 0) return false;
        out = at(newton_step(c, r.root[best]).root());
        return true;
    }
    const LinearMachine& m;
    double T_red, inv_dL;
    double c[5] = {1.0, 0.0, 0.0, 0.0, 0.0};
};

// A current as an affine function of an angle th (on the voltage ellipse or the current circle),
// in the variable u = tan((th - pi) / 2) of the limit quartics below:
// i = a + b cos th + g sin th, cos th = 1 - 2h, sin th = -2uh, h = 1 / (1 + u^2).
struct AngleMap {
    double ad = 0, bd = 0, gd = 0, aq = 0, bq = 0, gq = 0;
    Point at(double u) const {
        const double h = 1.0 / (1.0 + u * u), cs = 1.0 - 2.0 * h, sn = -2.0 * u * h;
        return {ad + bd * cs + gd * sn, aq + bq * cs + gq * sn};
    }
    // The point of root estimate u of the limit's quartic c after newton_step; the step is taken
    // only if it lowered |c| and ends below u1_below (a root's side condition).
    Point polished_at(const double (&c)[5], double u, double u1_below = INFINITY) const {
        const NewtonStep st = newton_step(c, u);
        return at(st.better && st.x1 < u1_below ? st.x1 : st.x0);
    }
};

// MTPV: on the ellipse, v = V_s (cos th, sin th) with V_s = V_max signed like omega, and
// i = M^-1 (v - (0, omega psi_m)) is affine in (cos th, sin th); T'(th) is then a quadratic form
// whose stationary points are the roots of a quartic in t = tan(th / 2). We use
// u = tan((th - pi) / 2) = -1 / t instead: the MTPV point (v mostly along -d for omega > 0, along
// +d for omega < 0, so th near pi either way) lies near u = 0, and the leading coefficient is the
// derivative at th = 0, far from it, so Ferrari's depressed form is well conditioned.
// cos th = 1 - 2h, sin th = -2uh, h = 1 / (1 + u^2).
struct MtpvQuartic : AngleMap {
    MtpvQuartic(const LinearMachine& m, double omega, double V_max) : m(m) {
        const double R = m.R_s, w = omega, psi = m.psi_m, dL = m.L_d - m.L_q, V = std::copysign(V_max, omega);
        const double det = R * R + w * w * m.L_d * m.L_q;
        valid = det > 0;
        const double inv_det = 1.0 / det;
        ad = -w * w * m.L_q * psi * inv_det, bd = R * V * inv_det, gd = w * m.L_q * V * inv_det;
        aq = -R * w * psi * inv_det, bq = -w * m.L_d * V * inv_det, gq = R * V * inv_det;
        const double a = dL * bd * bq, b = dL * gd * gq, k = dL * (bd * gq + gd * bq);
        const double d = psi * bq + dL * (ad * bq + bd * aq);
        const double e = psi * gq + dL * (ad * gq + gd * aq);
        c[0] = k + e, c[1] = 2.0 * d - 4.0 * (b - a), c[2] = -6.0 * k, c[3] = 4.0 * (b - a) + 2.0 * d, c[4] = k - e;
    }
    bool point(const RealRoots& r, Point& out) const {
        if (!valid) return false;
        // Candidates: the stationary points, and th = 0 (u = infinity), where the degree drops.
        double best_T = reduced_torque(m, ad + bd, aq + bq);
        int best = -1;
        for (int j = 0; j < r.count; ++j) {
            const Point p = at(r.root[j]);
            const double T = reduced_torque(m, p.i_d, p.i_q);
            if (T > best_T) best_T = T, best = j;
        }
        if (!std::isfinite(best_T)) return false;
        out = best < 0 ? Point{ad + bd, aq + bq} : polished_at(c, r.root[best]);
        return true;
    }
    const LinearMachine& m;
    bool valid;
    double c[5];
};

// The current circle meets the voltage ellipse: on the circle, i = I (cos ph, sin ph), |v|^2 = V^2
// is a quadratic form in (cos, sin), a quartic in tan(ph / 2). Again in u = tan((ph - pi) / 2):
// i = (-I, 0) is u = 0, the field-weakening intersections (i_d < 0 < i_q) have u in (-1, 0), and
// the leading coefficient is |v|^2 - V^2 at i = (I, 0), far outside the ellipse. i_q > 0 <=> u < 0.
struct IntersectionQuartic : AngleMap {
    IntersectionQuartic(const LinearMachine& m, double omega, double V_max, double I) : m(m) {
        bd = I, gq = I;  // i = I (cos th, sin th)
        const double R = m.R_s, w = omega, psi = m.psi_m, dL = m.L_d - m.L_q;
        const double A = I * I * w * w * m.L_d * m.L_d, B = I * I * w * w * m.L_q * m.L_q;
        const double C = 2.0 * I * I * R * w * dL, D = 2.0 * I * w * w * psi * m.L_d;
        const double E = 2.0 * I * w * R * psi, F = I * I * R * R + w * w * psi * psi - V_max * V_max;
        c[0] = A + D + F, c[1] = -2.0 * (C + E), c[2] = 2.0 * (F - A) + 4.0 * B, c[3] = 2.0 * (C - E), c[4] = A - D + F;
    }
    bool point(const RealRoots& r, Point& out) const {
        // The intersection with i_q > 0 (u < 0) and the most torque.
        double best_T = -INFINITY;
        int best = -1;
        for (int j = 0; j < r.count; ++j) {
            if (!(r.root[j] < 0)) continue;
            const Point p = at(r.root[j]);
            const double T = reduced_torque(m, p.i_d, p.i_q);
            if (T > best_T) best_T = T, best = j;
        }
        if (best < 0) return false;
        out = polished_at(c, r.root[best], 0.0);  // i_q > 0 <=> u < 0
        return true;
    }
    const LinearMachine& m;
    double c[5];
};

}  // namespace ipmsm::linear::conditions
