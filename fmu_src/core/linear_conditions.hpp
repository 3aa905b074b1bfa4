// The linear machine's optimality conditions, each as one quartic c[0] x^4 + ... + c[4] = 0 and
// the rule that reads its point from the real roots (used by linear_optimal_current.cpp only).
// The roots come unpolished from Ferrari's fast path (quartic.hpp), alone or two quartics
// together; the rule chooses among them, then polishes only the chosen root on c. All for the
// T' >= 0 side (linear_optimal_current.hpp) and a salient machine (L_d != L_q).
#pragma once

#include <algorithm>
#include <cmath>

#include "linear_optimal_current.hpp"
#include "quartic.hpp"

namespace ipmsm::linear::conditions {

// On the torque curve, i_d from i_q: T' = i_q (psi_m + dL i_d).
inline double i_d_on_torque_curve(const LinearMachine& m, double T_red, double i_q) {
    return (T_red / i_q - m.psi_m) / (m.L_d - m.L_q);
}

inline RealRoots roots_of(const double (&c)[5]) { return centred_quartic_roots(c[0], c[1], c[2], c[3], c[4]); }

// One Newton step on the quartic c from x: the rule of polish_quartic_root, with both ends
// kept, so that a caller maps both to a point at once (the two divisions overlap the second
// evaluation of c instead of following it) and selects.
struct NewtonStep {
    double x0, x1;
    bool better;  // |c(x1)| < |c(x0)|: take x1 (false for NaN)
};

inline NewtonStep newton_step(const double (&c)[5], double x) {
    const double f = (((c[0] * x + c[1]) * x + c[2]) * x + c[3]) * x + c[4];
    const double df = ((4.0 * c[0] * x + 3.0 * c[1]) * x + 2.0 * c[2]) * x + c[3];
    const double x1 = x - f / df;
    const double f1 = (((c[0] * x1 + c[1]) * x1 + c[2]) * x1 + c[3]) * x1 + c[4];
    return {x, x1, std::fabs(f1) < std::fabs(f)};
}

// p1 if take, else p0, per component (a select, not a branch: `take` is a coin toss for a root
// that is exact to rounding already).
inline Point choose(bool take, Point p1, Point p0) {
    return {take ? p1.i_d : p0.i_d, take ? p1.i_q : p0.i_q};
}

// The roots come in four slots, the unused ones 0 (RealRoots). The rules below look at all four
// with selects instead of branches: on random operating points the number of roots and the
// winner are unpredictable, and a mispredicted branch costs more than the extra arithmetic.

// Case i (MTPA) for a salient machine: dL^2 i_q^4 + psi_m T' i_q - T'^2 = 0, monic; exactly one
// positive root (psi_m >= 0, T' > 0).
struct MtpaQuartic {
    MtpaQuartic(const LinearMachine& m, double T_red) : m(m) {
        const double dL = m.L_d - m.L_q, k = 1.0 / (dL * dL);
        c[3] = m.psi_m * T_red * k;
        c[4] = -T_red * T_red * k;
    }
    bool point(const RealRoots& r, Point& out) const {
        double i_q = 0;  // the unused slots (0) do not change the largest root
        for (int j = 0; j < 4; ++j) i_q = std::max(i_q, r.root[j]);
        if (!(i_q > 0)) return false;
        // The MTPA condition psi_m i_d + dL (i_d^2 - i_q^2) = 0, solved for i_d without
        // cancellation (and without dividing by dL).
        const double dL = m.L_d - m.L_q;
        auto at = [&](double y) {
            const double s = std::sqrt(m.psi_m * m.psi_m + 4.0 * dL * dL * y * y);
            return Point{2.0 * dL * y * y / (m.psi_m + s), y};
        };
        const NewtonStep st = newton_step(c, i_q);
        const Point p0 = at(st.x0), p1 = at(st.x1);
        out = choose(st.better, p1, p0);
        return true;
    }
    const LinearMachine& m;
    double c[5] = {1.0, 0.0, 0.0, 0.0, 0.0};
};

// Case ii for a salient machine: the torque curve T' meets the voltage ellipse (with R_s), a
// depressed quartic in i_q.
struct VoltageLimitQuartic {
    VoltageLimitQuartic(const LinearMachine& m, double omega, double V_max, double T_red) : m(m), T_red(T_red) {
        const double R = m.R_s, w = omega, dL = m.L_d - m.L_q, psi = m.psi_m;
        const double zq = R * R + w * w * m.L_q * m.L_q;
        const double inv_a4 = 1.0 / (dL * dL * zq);
        c[2] = (psi * psi * zq + 2.0 * R * w * dL * dL * T_red - V_max * V_max * dL * dL) * inv_a4;
        c[3] = -2.0 * psi * T_red * (R * R + w * w * m.L_d * m.L_q) * inv_a4;
        c[4] = T_red * T_red * (R * R + w * w * m.L_d * m.L_d) * inv_a4;
    }
    bool point(const RealRoots& r, Point& out) const {
        // Every intersection is on the ellipse; the current along the torque curve has its minimum
        // at the MTPA point (outside the ellipse here), so the best is the intersection with the
        // least current. (For the usual geometry that is the root with the largest i_q.)
        double best = INFINITY, best_i_q = 0;
        for (int k = 0; k < 4; ++k) {
            const double i_q = r.root[k];
            const double i_d = i_d_on_torque_curve(m, T_red, i_q);
            const double I2 = i_d * i_d + i_q * i_q;
            const bool take = k < r.count && i_q > 0 && I2 < best;
            best = take ? I2 : best;
            best_i_q = take ? i_q : best_i_q;
        }
        if (!(best < INFINITY)) return false;
        const NewtonStep st = newton_step(c, best_i_q);
        const double i_d0 = i_d_on_torque_curve(m, T_red, st.x0), i_d1 = i_d_on_torque_curve(m, T_red, st.x1);
        out = choose(st.better, Point{i_d1, st.x1}, Point{i_d0, st.x0});
        return true;
    }
    const LinearMachine& m;
    double T_red;
    double c[5] = {1.0, 0.0, 0.0, 0.0, 0.0};
};

// MTPV: on the ellipse, v = V (cos th, sin th) and i = M^-1 (v - (0, omega psi_m)) is affine in
// (cos th, sin th); T'(th) is then a quadratic form whose stationary points are the roots of a
// quartic in t = tan(th / 2). We use u = tan((th - pi) / 2) = -1 / t instead: the MTPV point (v
// mostly along -d) lies near u = 0 and the leading coefficient is the derivative at th = 0, far
// from it, so the fast path is well conditioned. cos th = 1 - 2h, sin th = -2uh, h = 1 / (1 + u^2).
struct MtpvQuartic {
    MtpvQuartic(const LinearMachine& m, double omega, double V_max) : m(m) {
        const double R = m.R_s, w = omega, psi = m.psi_m, dL = m.L_d - m.L_q;
        const double det = R * R + w * w * m.L_d * m.L_q;
        valid = det > 0;
        const double inv_det = 1.0 / det;
        ad = -w * w * m.L_q * psi * inv_det, bd = R * V_max * inv_det, gd = w * m.L_q * V_max * inv_det;
        aq = -R * w * psi * inv_det, bq = -w * m.L_d * V_max * inv_det, gq = R * V_max * inv_det;
        const double a = dL * bd * bq, b = dL * gd * gq, k = dL * (bd * gq + gd * bq);
        const double d = psi * bq + dL * (ad * bq + bd * aq);
        const double e = psi * gq + dL * (ad * gq + gd * aq);
        c[0] = k + e, c[1] = 2.0 * d - 4.0 * (b - a), c[2] = -6.0 * k, c[3] = 4.0 * (b - a) + 2.0 * d, c[4] = k - e;
    }
    Point at(double u) const {
        const double h = 1.0 / (1.0 + u * u), cs = 1.0 - 2.0 * h, sn = -2.0 * u * h;
        return {ad + bd * cs + gd * sn, aq + bq * cs + gq * sn};
    }
    bool point(const RealRoots& r, Point& out) const {
        if (!valid) return false;
        // Candidates: the stationary points, and th = 0 (u = infinity), where the degree drops.
        double best = reduced_torque(m, ad + bd, aq + bq), best_u = INFINITY;
        for (int j = 0; j < 4; ++j) {
            const Point p = at(r.root[j]);
            const double T = reduced_torque(m, p.i_d, p.i_q);
            const bool take = j < r.count && T > best;
            best = take ? T : best;
            best_u = take ? r.root[j] : best_u;
        }
        if (best_u == INFINITY) {
            out = Point{ad + bd, aq + bq};
        } else {
            const NewtonStep st = newton_step(c, best_u);
            const Point p0 = at(st.x0), p1 = at(st.x1);
            out = choose(st.better, p1, p0);
        }
        return std::isfinite(best);
    }
    const LinearMachine& m;
    bool valid;
    double ad, bd, gd, aq, bq, gq;  // i = (ad + bd cos + gd sin, aq + bq cos + gq sin)
    double c[5];
};

// The current circle meets the voltage ellipse: on the circle, i = I (cos ph, sin ph), |v|^2 = V^2
// is a quadratic form in (cos, sin), a quartic in tan(ph / 2). Again in u = tan((ph - pi) / 2):
// i = (-I, 0) is u = 0, the field-weakening intersections (i_d < 0 < i_q) have u in (-1, 0), and
// the leading coefficient is |v|^2 - V^2 at i = (I, 0), far outside the ellipse. i_q > 0 <=> u < 0.
struct IntersectionQuartic {
    IntersectionQuartic(const LinearMachine& m, double omega, double V_max, double I) : m(m), I(I) {
        const double R = m.R_s, w = omega, psi = m.psi_m, dL = m.L_d - m.L_q;
        const double A = I * I * w * w * m.L_d * m.L_d, B = I * I * w * w * m.L_q * m.L_q;
        const double C = 2.0 * I * I * R * w * dL, D = 2.0 * I * w * w * psi * m.L_d;
        const double E = 2.0 * I * w * R * psi, F = I * I * R * R + w * w * psi * psi - V_max * V_max;
        c[0] = A + D + F, c[1] = -2.0 * (C + E), c[2] = 2.0 * (F - A) + 4.0 * B, c[3] = 2.0 * (C - E), c[4] = A - D + F;
    }
    Point at(double u) const {
        const double h = 1.0 / (1.0 + u * u);
        return {I * (1.0 - 2.0 * h), -2.0 * I * u * h};
    }
    bool point(const RealRoots& r, Point& out) const {
        double best = -INFINITY, best_u = 0;
        for (int j = 0; j < 4; ++j) {
            const Point p = at(r.root[j]);
            const double T = reduced_torque(m, p.i_d, p.i_q);
            const bool take = j < r.count && r.root[j] < 0 && T > best;
            best = take ? T : best;
            best_u = take ? r.root[j] : best_u;
        }
        if (!(best > -INFINITY)) return false;
        const NewtonStep st = newton_step(c, best_u);
        const Point p0 = at(st.x0), p1 = at(st.x1);
        out = choose(st.better && st.x1 < 0, p1, p0);
        return true;
    }
    const LinearMachine& m;
    double I;
    double c[5];
};

}  // namespace ipmsm::linear::conditions
