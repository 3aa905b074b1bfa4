// The linear machine's optimality conditions, each as one quartic c[0] x^4 + ... + c[4] = 0 and
// the rule that reads its point from the real roots (used by linear_optimal_current.cpp only).
// The roots come unpolished from Ferrari's fast path (quartic_fast.hpp); the rule chooses among
// them, then polishes only the chosen root on c (MTPV and the intersection also take a root
// polished by Halley's method from elsewhere, through at()). All for the
// T' >= 0 side (linear_optimal_current.hpp) and a salient machine (L_d != L_q).
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "control/linear_optimal_current.hpp"
#include "numerics/quartic.hpp"
#include "numerics/quartic_fast.hpp"

namespace ipmsm::linear::conditions {

inline RealRoots roots_of(const double (&c)[5]) { return centred_quartic_roots(c[0], c[1], c[2], c[3], c[4]); }

// Selects rather than branches (fast::select): on random operating points the winning root and
// the polish's decision are unpredictable, and a mispredicted branch costs more than computing
// both candidates.
using fast::select;

// After newton_step: the point of x1 if `take`, else of x0. The rules that use it compute both
// points first (p0, p1), so that their divisions overlap the step's second evaluation of the quartic.
// (A shared helper taking at() as a lambda was tried: GCC did not inline it, 5 % slower; the limit
// quartics share AngleMap::polished_at(), MTPA's own at() stays in its rule.)
inline Point choose(bool take, Point p1, Point p0) {
    return {select(take, p1.i_d, p0.i_d), select(take, p1.i_q, p0.i_q)};
}

// Arg-max and arg-min without branches: a key with the candidate's slot (0..7) in its lowest
// three mantissa bits; std::max/min of keys (maxsd/minsd) then carries the slot along. Ties
// closer than 2^-49 relative go by slot. Keys must be finite (clamp +-inf to +-DBL_MAX first).
inline double tagged(double key, unsigned slot) {
    std::uint64_t bits;
    std::memcpy(&bits, &key, sizeof bits);
    bits = (bits & ~std::uint64_t{7}) | slot;
    std::memcpy(&key, &bits, sizeof key);
    return key;
}

inline unsigned slot_of(double key) {
    std::uint64_t bits;
    std::memcpy(&bits, &key, sizeof bits);
    return static_cast<unsigned>(bits & 7);
}

// The roots come in four slots, the unused ones 0 (RealRoots). The rules below look at all four
// (each says why an unused slot cannot win) and pick with keys and selects, not branches.

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

// The largest Newton step, relative to the root, that VoltageLimitQuartic::point() takes from
// the fast path's unpolished root (its genuine corrections are ~1e-10 relative or less).
constexpr double kNewtonStepMax = 0x1p-24;

// Case ii for a salient machine: the torque curve T' meets the voltage ellipse (with R_s), a
// depressed quartic in i_q.
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
    bool point(const RealRoots& r, Point& out) const {
        double inv[4];
        fast::with_inverses(r, inv);
        return point(r, inv, out);
    }
    // With the roots' reciprocals (+inf in the unused slots), from the fast path.
    bool point(const RealRoots& r, const double (&inv)[4], Point& out) const {
        // Every intersection is on the ellipse; the current along the torque curve has its minimum
        // at the MTPA point (outside the ellipse here), so the best is the intersection with the
        // least current. (For the usual geometry that is the root with the largest i_q.)
        // Key: the current squared; DBL_MAX for i_q <= 0 (also the unused slots, whose infinite
        // reciprocal makes i_d infinite), by max with +-DBL_MAX signed like -i_q.
        double best = DBL_MAX;
        for (unsigned k = 0; k < 4; ++k) {
            const double i_q = r.root[k];
            const double i_d = (T_red * inv[k] - m.psi_m) * inv_dL;
            const double I2 = std::min(i_d * i_d + i_q * i_q, DBL_MAX);
            best = std::min(best, tagged(std::max(I2, std::copysign(DBL_MAX, -i_q)), k));
        }
        if (!(best < 0.5 * DBL_MAX)) return false;
        const unsigned slot = slot_of(best);
        const double x0 = r.root[slot];
        // One Newton step, taken if it is small: a genuine correction of a root that the fast path
        // gives to ~1e-10 or better (at a double root p and p' are rounding noise and the step
        // arbitrary). The size test needs no second evaluation of the quartic, and i_d follows to
        // first order, T'/x = (T'/x0) (1 - dx/x0) + O(dx^2): no division after the step. Both
        // shorten the chain that every field-weakening command waits for.
        const double inv_x0 = inv[slot];
        const QuarticValue v = quartic_value(c, x0);
        const double dx = -v.f / v.df;
        const double x = x0 + select(std::fabs(dx) <= kNewtonStepMax * std::fabs(x0), dx, 0.0);
        const double T_over_x = T_red * inv_x0 * (1.0 - (x - x0) * inv_x0);
        out = Point{(T_over_x - m.psi_m) * inv_dL, x};
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
        const Point p0 = at(st.x0), p1 = at(st.x1);
        return choose(st.better && st.x1 < u1_below, p1, p0);
    }
};

// MTPV: on the ellipse, v = V_s (cos th, sin th) with V_s = V_max signed like omega, and
// i = M^-1 (v - (0, omega psi_m)) is affine in (cos th, sin th); T'(th) is then a quadratic form
// whose stationary points are the roots of a quartic in t = tan(th / 2). We use
// u = tan((th - pi) / 2) = -1 / t instead: the MTPV point (v mostly along -d for omega > 0, along
// +d for omega < 0, so th near pi either way) lies near u = 0, and the leading coefficient is the
// derivative at th = 0, far from it, so the fast path is well conditioned (and LimitPolish's
// lossless seed is close: with V_max unsigned, omega < 0 put the point near |u| = 6 on the default
// motor, where two Halley steps left 4e-9 instead of rounding).
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
        // An unused slot (u = 0) is a point on the ellipse, never above its maximum: harmless.
        double best = tagged(std::max(reduced_torque(m, ad + bd, aq + bq), -DBL_MAX), 4);
        for (unsigned j = 0; j < 4; ++j) {
            const Point p = at(r.root[j]);
            best = std::max(best, tagged(std::max(reduced_torque(m, p.i_d, p.i_q), -DBL_MAX), j));
        }
        const unsigned k = slot_of(best);
        const double best_u = k < 4 ? r.root[k] : INFINITY;
        out = best_u == INFINITY ? Point{ad + bd, aq + bq} : polished_at(c, best_u);
        return std::fabs(best) < DBL_MAX;
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
        // Key: the torque; -DBL_MAX for u >= 0 (i_q <= 0, also the unused slots), by min with
        // +-DBL_MAX signed like -u.
        double best = -DBL_MAX;
        for (unsigned j = 0; j < 4; ++j) {
            const Point p = at(r.root[j]);
            const double T = std::max(reduced_torque(m, p.i_d, p.i_q), -DBL_MAX);
            best = std::max(best, tagged(std::min(T, std::copysign(DBL_MAX, -r.root[j])), j));
        }
        if (!(best > -0.5 * DBL_MAX)) return false;
        out = polished_at(c, r.root[slot_of(best)], 0.0);  // i_q > 0 <=> u < 0
        return true;
    }
    const LinearMachine& m;
    double c[5];
};

}  // namespace ipmsm::linear::conditions
