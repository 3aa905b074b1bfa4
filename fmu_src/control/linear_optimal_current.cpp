#include "control/linear_optimal_current.hpp"

#include <algorithm>
#include <cmath>

#include "control/linear_conditions.hpp"
#include "numerics/quartic.hpp"
#include "numerics/quartic_fast.hpp"

namespace ipmsm::linear {
using namespace conditions;  // the quartic of each condition
namespace {

// Relative slack on the limits, so that a point computed *on* a limit counts as within it.
constexpr double kLimitSlack = 1e-9;

// T_max with R_s differs from the lossless estimate by less than this (the default motor at
// 1500..12000 r/min: within 3.0 %): a polished T_max further off is not trusted (a plausibility
// check; the KKT signs in LimitPolish::finish() are what rule out the other stationary points),
// and a command further above is clamped without solving its quartic.
constexpr double kEstimateMargin = 0.05;

// Below this |L_d - L_q| / max(L_d, L_q) the machine is treated as non-salient (surface PM).
constexpr double kNonSalient = 1e-9;

// |L_d - L_q| <= ratio max(L_d, L_q).
bool saliency_at_most(const LinearMachine& m, double ratio) {
    return std::abs(m.L_d - m.L_q) <= ratio * std::max(std::abs(m.L_d), std::abs(m.L_q));
}

bool non_salient(const LinearMachine& m) { return saliency_at_most(m, kNonSalient); }

// Below this |L_d - L_q| / max(L_d, L_q) Case ii is solved by Newton's method from the non-salient
// point instead of its quartic in i_q: as L_d - L_q -> 0 the torque curve becomes the line
// i_q = T'/psi_m, the quartic's two roots of interest merge into a double root there (its
// accuracy falls to sqrt(eps)) and i_d = (T'/i_q - psi_m) / (L_d - L_q) divides their error by
// L_d - L_q: at 1e-3 the quartic's point broke V_max by 400 %, at 1e-2 by 3e-11.
constexpr double kNearlyNonSalient = 0.02;
// Newton on the torque curve and the voltage ellipse: at most this many steps, to this relative step.
constexpr int kCaseIiNewtonSteps = 20;
constexpr double kCaseIiNewtonTol = 1e-14;

bool nearly_non_salient(const LinearMachine& m) { return saliency_at_most(m, kNearlyNonSalient); }

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

// A gradient with respect to (i_d, i_q).
struct Gradient {
    double d, q;
    double along(double t_d, double t_q) const { return d * t_d + q * t_q; }
};

// Half the gradient of |v|^2 at a current.
Gradient half_voltage_gradient(const LinearMachine& m, double omega, Point p) {
    const double v_d = m.R_s * p.i_d - omega * m.L_q * p.i_q;
    const double v_q = m.R_s * p.i_q + omega * (m.L_d * p.i_d + m.psi_m);
    return {v_d * m.R_s + v_q * omega * m.L_d, -v_d * omega * m.L_q + v_q * m.R_s};
}

// The gradient of T' = psi_m i_q + (L_d - L_q) i_d i_q.
Gradient torque_gradient(const LinearMachine& m, Point p) {
    const double dL = m.L_d - m.L_q;
    return {dL * p.i_q, m.psi_m + dL * p.i_d};
}

// Half the gradient of |i|^2.
Gradient half_current_gradient(Point p) { return {p.i_d, p.i_q}; }

// The KKT sign tests of the limits: moving along the curve whose normal is `curve` (the tangent
// (-curve.q, curve.d)), the product of the rates of change of a and b.
double rates_along(Gradient curve, Gradient a, Gradient b) {
    const double t_d = -curve.q, t_q = curve.d;
    return a.along(t_d, t_q) * b.along(t_d, t_q);
}

// V_max^2 with the slack, so that a point computed on the voltage limit counts as within it.
double voltage_limit_sq(const OperatingLimits& lim) { return lim.V_max * lim.V_max * (1.0 + kLimitSlack); }

bool within_voltage(const LinearMachine& m, const OperatingLimits& lim, Point p) {
    return voltage_sq(m, lim.omega, p.i_d, p.i_q) <= voltage_limit_sq(lim);
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
    Point p{0.0, 0.0};  // stays 0 if no torque is producible (psi_m = 0 and dL = 0)
    if (non_salient(m)) {
        if (m.psi_m > 0) p.i_q = T_red / m.psi_m;
        return p;
    }
    const MtpaQuartic Q(m, T_red);
    Q.point(roots_of(Q.c), p);
    return p;
}

namespace {

// i_d of MTPA at a current magnitude, from its square I2 (closed form, cancellation-free).
double mtpa_i_d_at_current_sq(const LinearMachine& m, double I2) {
    const double dL = m.L_d - m.L_q;
    const double denom = m.psi_m + std::sqrt(m.psi_m * m.psi_m + 8.0 * dL * dL * I2);
    return denom > 0 ? 2.0 * dL * I2 / denom : 0.0;
}

}  // namespace

Point mtpa_at_current(const LinearMachine& m, double I) {
    const double I2 = I * I, i_d = mtpa_i_d_at_current_sq(m, I2);
    return {i_d, std::sqrt(std::max(0.0, I2 - i_d * i_d))};
}

namespace {

// Case ii of a nearly non-salient machine: the non-salient point (i_q = T'/psi_m on the ellipse,
// the larger i_d: the least current), exact for L_d = L_q, then Newton on T'(i) = T_red and
// |v(i)|^2 = V_max^2. false if that line misses the ellipse (a command near T_max, where the
// curve's bend matters) or Newton does not converge (the curve nearly tangent to the ellipse).
bool voltage_limit_by_newton(const LinearMachine& m, double omega, double V_max, double T_red, Point& out) {
    if (!(m.psi_m > 0)) return false;
    Point p{0.0, T_red / m.psi_m};
    if (!i_d_on_ellipse(m, omega, V_max, p.i_q, p.i_d)) return false;
    bool converged = non_salient(m);  // then the point is exact
    for (int k = 0; k < kCaseIiNewtonSteps && !converged; ++k) {
        const double f_T = reduced_torque(m, p.i_d, p.i_q) - T_red;
        const double f_V = voltage_sq(m, omega, p.i_d, p.i_q) - V_max * V_max;
        const Gradient t = torque_gradient(m, p), g = half_voltage_gradient(m, omega, p);
        const double a = t.d, b = t.q, c = 2.0 * g.d, d = 2.0 * g.q;
        const double det = a * d - b * c;
        if (!(std::abs(det) > 0)) return false;
        const double dd = (f_T * d - b * f_V) / det, dq = (a * f_V - c * f_T) / det;
        p.i_d -= dd, p.i_q -= dq;
        if (!(std::isfinite(p.i_d) && std::isfinite(p.i_q))) return false;
        converged = std::hypot(dd, dq) <= kCaseIiNewtonTol * std::hypot(p.i_d, p.i_q);
    }
    out = p;
    return converged;
}

}  // namespace

bool voltage_limit(const LinearMachine& m, double omega, double V_max, double T_red, Point& out) {
    if (nearly_non_salient(m) && voltage_limit_by_newton(m, omega, V_max, T_red, out)) return true;
    if (non_salient(m)) return false;  // the quartic degenerates
    const VoltageLimitQuartic Q(m, omega, V_max, T_red);
    return Q.point(roots_of(Q.c), out);
}

bool voltage_limit_is_optimal(const LinearMachine& m, double omega, Point p) {
    // Along the torque curve, |i|^2 and |v|^2 change in opposite directions (or not at all).
    return rates_along(torque_gradient(m, p), half_current_gradient(p), half_voltage_gradient(m, omega, p)) <= 0.0;
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
    const MtpvQuartic Q(m, omega, V_max);
    return Q.valid && Q.point(roots_of(Q.c), out);
}

bool current_voltage_intersection(const LinearMachine& m, double omega, double V_max, double I,
                                  Point& out) {
    const IntersectionQuartic Q(m, omega, V_max, I);
    return Q.point(roots_of(Q.c), out);
}

namespace {

// T_max in field weakening, estimated for the lossless (R_s = 0) machine, where it is closed
// form. It says which limit applies (is the MTPV point inside the current circle?) and seeds
// LimitPolish with its point; the result always comes from the machine with R_s. In flux
// coordinates lambda = (psi_m + L_d i_d, L_q i_q) on the circle
// |lambda| = V/omega the torque lambda_q (psi_m L_q + dL lambda_d) / (L_d L_q) is stationary
// where 2 dL lambda_d^2 + psi_m L_q lambda_d - dL (V/omega)^2 = 0 (MTPV); the current circle
// meets the ellipse where (L_d^2 - L_q^2) i_d^2 + 2 psi_m L_d i_d + psi_m^2 + L_q^2 I^2 = (V/omega)^2.
struct LimitEstimate {
    bool mtpv;     // the MTPV point is inside the current circle
    double T_red;  // the lossless T_max (NaN if the estimate fails)
    Point p;       // where it is (the seed of LimitPolish)
};

LimitEstimate lossless_limit_estimate(const LinearMachine& m, const OperatingLimits& lim) {
    const double dL = m.L_d - m.L_q, Lam2 = lim.V_max * lim.V_max / (lim.omega * lim.omega);
    const double I2 = lim.I_max * lim.I_max;
    double lam_d = 0.0;  // non-salient: MTPV at lambda_d = 0
    if (!non_salient(m)) {
        const double root = std::sqrt(m.psi_m * m.psi_m * m.L_q * m.L_q + 8.0 * dL * dL * Lam2);
        // The stationary point with the larger torque: lambda_d of the same sign as -dL.
        lam_d = (-m.psi_m * m.L_q - std::copysign(root, dL)) * (0.25 / dL);
    }
    const double lam_q = std::sqrt(std::max(0.0, Lam2 - lam_d * lam_d));
    // Reciprocals of machine constants: their divisions run beside the chain, not in it.
    const double i_d = (lam_d - m.psi_m) * (1.0 / m.L_d), i_q = lam_q * (1.0 / m.L_q);
    if (i_d * i_d + i_q * i_q <= I2) return {true, reduced_torque(m, i_d, i_q), {i_d, i_q}};
    // The quadratic in i_d, cancellation-free (a = 0 only for non-salient machines: one root).
    const double a = m.L_d * m.L_d - m.L_q * m.L_q, b = 2.0 * m.psi_m * m.L_d;
    const double c = m.psi_m * m.psi_m + m.L_q * m.L_q * I2 - Lam2;
    const double t = -0.5 * (b + std::copysign(std::sqrt(b * b - 4.0 * a * c), b));  // NaN: no intersection
    const double roots[2] = {t * (1.0 / a), c / t};
    LimitEstimate e{false, NAN, {0.0, 0.0}};
    for (double x : roots) {
        if (!(x * x <= I2)) continue;
        const Point p{x, std::sqrt(I2 - x * x)};
        const double T_x = reduced_torque(m, p.i_d, p.i_q);
        if (!(T_x <= e.T_red)) e = {false, T_x, p};  // the larger (NaN at first)
    }
    return e;
}

// The torque at which MTPA meets the voltage ellipse at this speed, estimated without a quartic:
// along the MTPA curve |v|^2 grows with the current; interpolated linearly in I^2 between i = 0
// and the MTPA point at I_max (|v|^2 = v1_sq > V_max^2 there), it gives the current I_b at the
// ellipse, and the MTPA torque at I_b. Wrong by a few per cent at most (192 of 101 427 random
// field-weakening commands on the default motor land on the other side), which costs the
// sequential path's extra quartics, never accuracy. Returned squared: the fast path compares
// T'^2 with it and needs neither the square root of I_b^2 nor of T_b^2 (this decides which
// quartic every field-weakening command solves, so how soon it is known matters).
double base_torque_sq_estimate(const LinearMachine& m, const OperatingLimits& lim, double v1_sq) {
    const double v0_sq = voltage_sq(m, lim.omega, 0.0, 0.0), V2 = lim.V_max * lim.V_max;
    // Above the corner speed the back-EMF alone exceeds V_max. (A branch: a select here, which
    // puts the division on every call's path to the MTPA / Case ii decision, was 10 ns slower.)
    if (!(V2 > v0_sq)) return 0.0;
    // MTPA at I_b, from I_b^2.
    const double I2 = lim.I_max * lim.I_max * (V2 - v0_sq) / (v1_sq - v0_sq);
    const double i_d = mtpa_i_d_at_current_sq(m, I2);
    const double k = m.psi_m + (m.L_d - m.L_q) * i_d;  // T' = i_q k
    return std::max(0.0, I2 - i_d * i_d) * k * k;
}

// At a point where the current circle meets the voltage ellipse: does moving along the ellipse
// towards more torque leave the circle? Then the current limit binds there (KKT), and T_max is
// at this point rather than at an MTPV point inside the circle.
bool current_limit_binds(const LinearMachine& m, double omega, Point p) {
    return rates_along(half_voltage_gradient(m, omega, p), torque_gradient(m, p), half_current_gradient(p)) > 0.0;
}

// At a point where the current circle meets the voltage ellipse: does moving along the circle
// towards more torque leave the ellipse? (The voltage limit's KKT multiplier is positive.)
// Ferrari's intersection takes the point of most torque and needs no such test; a polished one does.
bool voltage_limit_binds(const LinearMachine& m, double omega, Point p) {
    return rates_along(half_current_gradient(p), torque_gradient(m, p), half_voltage_gradient(m, omega, p)) > 0.0;
}

// The limit checks, shared by the sequential and the fast field-weakening paths.
bool mtpv_limit_at(const LinearMachine& m, const OperatingLimits& lim, Point p, double T_base, Limit& out) {
    if (!(p.i_d * p.i_d + p.i_q * p.i_q <= lim.I_max * lim.I_max * (1.0 + kLimitSlack))) return false;
    const double T = reduced_torque(m, p.i_d, p.i_q);
    if (!(T >= 0)) return false;
    out = {p, T, Region::mtpv, true, T_base};
    return true;
}

bool intersection_limit_at(const LinearMachine& m, Point p, double T_base, Limit& out) {
    const double T = reduced_torque(m, p.i_d, p.i_q);
    if (!(T >= 0)) return false;
    out = {p, T, Region::current_and_voltage_limit, true, T_base};
    return true;
}

// max_torque() given the MTPA point at I_max and its squared voltage.
Limit max_torque_from(const LinearMachine& m, const OperatingLimits& lim, Point p1, double v1) {
    if (v1 <= voltage_limit_sq(lim))
        return {p1, reduced_torque(m, p1.i_d, p1.i_q), Region::mtpa, true, INFINITY};
    const double T_base = std::sqrt(base_torque_sq_estimate(m, lim, v1));
    // Field weakening: T_max is at MTPV if that point is inside the current circle, else where
    // the circle meets the ellipse. One quartic decides in nearly all cases.
    auto mtpv_limit = [&](Limit& out) {
        Point p;
        return mtpv(m, lim.omega, lim.V_max, p) && mtpv_limit_at(m, lim, p, T_base, out);
    };
    auto intersection_limit = [&](Limit& out) {
        Point p;
        return current_voltage_intersection(m, lim.omega, lim.V_max, lim.I_max, p) &&
               intersection_limit_at(m, p, T_base, out);
    };
    Limit top;
    if (lossless_limit_estimate(m, lim).mtpv) {
        if (mtpv_limit(top) || intersection_limit(top)) return top;
    } else if (intersection_limit(top)) {
        Limit inside;
        if (!current_limit_binds(m, lim.omega, top.point) && mtpv_limit(inside)) return inside;
        return top;
    } else if (mtpv_limit(top)) {
        return top;
    }
    // Above the maximum speed: no current within I_max brings the voltage within V_max.
    return {{-lim.I_max, 0.0}, 0.0, Region::zero_torque, false, 0.0};
}

// T_max in field weakening as MATH.md allows it with R_s: the lossless (R_s = 0) closed form,
// polished on the limit's own quartic (MTPV or the intersection, in its u) by Halley's method,
// in place of a second Ferrari solution. Two steps, taken one at a time by advance() so that the
// command's Ferrari solution can interleave them: from the lossless seed (within 3 % in torque
// on the default motor) they leave at most 1.4e-16 (the size of a third step, relative to 1 + |u|,
// on 1.7e5 random field-weakening operating points): rounding. finish() confirms that without a
// division: the Newton correction f / f' at the result must be below kHalleyTol
// (|f| <= kHalleyTol |f'| (1 + |u|)); where R_s is large against omega L the seed is further off
// and up to kHalleyExtraSteps more steps are taken (never on the default motor; on about a third
// of the unit tests' random small machines). Then the point must be the limit, not another root
// of its quartic, which Ferrari's path rules out by comparing all roots: MTPV a maximum of the
// torque along the ellipse (f' < 0: f is dT/dth times a positive factor) within the current
// limit; the intersection a KKT point (both limits bind: current_limit_binds and
// voltage_limit_binds); and the torque within kEstimateMargin of the estimate. false sends the
// caller to the other limit (other()), then to the all-Ferrari sequential path.
constexpr int kHalleySteps = 2, kHalleyExtraSteps = 2;
constexpr double kHalleyTol = 1e-12;  // the remaining Newton correction, relative to 1 + |u|

struct LimitPolish {
    double c[5];
    double u;      // the limit's angle variable (MtpvQuartic, IntersectionQuartic)
    AngleMap map;  // the limit's point from u
    bool mtpv, valid;
    int steps = 0;  // Halley steps taken
    // Seeded by the lossless estimate's point.
    LimitPolish(const LinearMachine& m, const OperatingLimits& lim, const LimitEstimate& e) : LimitPolish(m, lim, e.mtpv) {
        if (mtpv) {
            // The lossless point's voltage, v = omega (-L_q i_q, L_d i_d + psi_m), |v| = V_max.
            u = voltage_angle(lim, -lim.omega * m.L_q * e.p.i_q, lim.omega * (m.L_d * e.p.i_d + m.psi_m));
        } else {
            u = -(lim.I_max + e.p.i_d) / e.p.i_q;  // the lossless point's angle on the circle
        }
    }
    void advance() {  // one Halley step
        const QuarticValue v = quartic_value(c, u);
        const double d2 = (12.0 * c[0] * u + 6.0 * c[1]) * u + 2.0 * c[2];
        u -= 2.0 * v.f * v.df / (2.0 * v.df * v.df - v.f * d2);
        ++steps;
    }
    // The Newton correction f / f' at u is below kHalleyTol (relative to 1 + |u|), without a division.
    static bool converged(const QuarticValue& v, double u) {
        return std::fabs(v.f) <= kHalleyTol * std::fabs(v.df) * (1.0 + std::fabs(u));
    }
    bool finish(const LinearMachine& m, const OperatingLimits& lim, const LimitEstimate& e, Limit& top) {
        constexpr double T_base = INFINITY;  // not estimated here (the fast path predicts with its square)
        if (!(valid && e.T_red > 0)) return false;
        QuarticValue v = quartic_value(c, u);
        for (int k = 0; k < kHalleyExtraSteps && !converged(v, u); ++k) {  // a seed further off (R_s large against omega L)
            advance();
            v = quartic_value(c, u);
        }
        if (!converged(v, u)) return false;
        const Point p = map.at(u);
        if (mtpv) {
            if (!(v.df < 0.0 && mtpv_limit_at(m, lim, p, T_base, top))) return false;
        } else {
            if (!(u < 0 && current_limit_binds(m, lim.omega, p) && voltage_limit_binds(m, lim.omega, p) &&
                  intersection_limit_at(m, p, T_base, top)))
                return false;
        }
        return std::abs(top.T_red - e.T_red) <= kEstimateMargin * e.T_red;
    }
    // The other limit, polished from this one's point. Near the speed where the MTPV point leaves
    // the current circle the lossless estimate can choose the wrong one (2 % of random
    // field-weakening points on the default motor); the two points are close there.
    LimitPolish other(const LinearMachine& m, const OperatingLimits& lim) const {
        const Point p = map.at(u);
        LimitPolish o(m, lim, !mtpv);
        if (o.mtpv) {  // p is on the voltage ellipse (with R_s)
            o.u = voltage_angle(lim, m.R_s * p.i_d - lim.omega * m.L_q * p.i_q,
                                m.R_s * p.i_q + lim.omega * (m.L_d * p.i_d + m.psi_m));
        } else {  // p is at the MTPV point, outside the current circle: its angle
            o.u = -(std::hypot(p.i_d, p.i_q) + p.i_d) / p.i_q;
        }
        while (o.steps < kHalleySteps) o.advance();
        return o;
    }

private:
    LimitPolish(const LinearMachine& m, const OperatingLimits& lim, bool mtpv) : mtpv(mtpv) {
        if (mtpv) {
            const MtpvQuartic Q(m, lim.omega, lim.V_max);
            std::copy(Q.c, Q.c + 5, c);
            map = Q, valid = Q.valid;
        } else {
            const IntersectionQuartic Q(m, lim.omega, lim.V_max, lim.I_max);
            std::copy(Q.c, Q.c + 5, c);
            map = Q, valid = true;
        }
    }
    // MtpvQuartic's u of a voltage v = V_s (cos th, sin th) on the ellipse (V_s = V_max signed like
    // omega): u = tan((th - pi) / 2) = -v_q / (V_s - v_d).
    static double voltage_angle(const OperatingLimits& lim, double v_d, double v_q) {
        return -v_q / (std::copysign(lim.V_max, lim.omega) - v_d);
    }
};

// Field weakening with a torque command: T_max by LimitPolish (the predicted limit, else the
// other one), the command by one Ferrari solution (MTPA or Case ii, predicted by the base-torque
// estimate) and the checks of the sequential path; a failed prediction or check returns false and
// the caller takes the sequential path. T_max's Halley steps run between the stages of the command's Ferrari
// solution. A command more than kEstimateMargin above the lossless T_max is clamped without
// solving its quartic; one just above T_max finds no valid Case ii point and is clamped too.
bool field_weakening_fast(const LinearMachine& m, const OperatingLimits& lim, double T_red, double v1,
                          Limit& top, Point& p, Region& region) {
    if (nearly_non_salient(m)) return false;  // Case ii by Newton (voltage_limit()): the sequential path
    const double T_base_sq = base_torque_sq_estimate(m, lim, v1);
    const LimitEstimate estimate = lossless_limit_estimate(m, lim);
    LimitPolish limit(m, lim, estimate);
    auto limit_step = [&] {  // called three times by the Ferrari stages: a step in the first two
        if (limit.steps < kHalleySteps) limit.advance();
    };
    bool command_ok;
    if (T_red > (1.0 + kEstimateMargin) * estimate.T_red) {
        command_ok = false;  // clamped whatever T_max's polish gives
    } else if (T_red * T_red <= T_base_sq) {
        const MtpaQuartic cq(m, T_red);
        region = Region::mtpa;
        command_ok = cq.point(fast::depressed_quartic_roots(cq.c[2], cq.c[3], cq.c[4], limit_step), p) &&
                     within_voltage(m, lim, p);
    } else {
        const VoltageLimitQuartic cq(m, lim.omega, lim.V_max, T_red);
        region = Region::voltage_limit;
        double inv[4];
        const RealRoots roots = fast::depressed_quartic_roots(cq.c[2], cq.c[3], cq.c[4], limit_step, inv);
        command_ok = cq.point(roots, inv, p) &&
                     voltage_limit_is_optimal(m, lim.omega, p);
    }
    while (limit.steps < kHalleySteps) limit.advance();  // clamped without a quartic, or a solver's early exit
    if (!limit.finish(m, lim, estimate, top) && !(estimate.T_red > 0 && limit.other(m, lim).finish(m, lim, estimate, top)))
        return false;
    if (T_red >= top.T_red) {  // clamped
        p = top.point;
        region = top.region;
        return true;
    }
    return command_ok;
}

}  // namespace

Limit max_torque(const LinearMachine& m, const OperatingLimits& lim) {
    const Point p1 = mtpa_at_current(m, lim.I_max);
    return max_torque_from(m, lim, p1, voltage_sq(m, lim.omega, p1.i_d, p1.i_q));
}

CommandSolver::CommandSolver(int pole_pairs) : kT_(torque_factor(pole_pairs)), inv_kT_(1.0 / kT_) {}

CurrentCommand CommandSolver::operator()(const LinearMachine& m, double T_ref, const OperatingLimits& lim) {
    // Mirror negative torque onto positive: (T, omega, i_q) -> (-T, -omega, -i_q).
    const double sign = fast::select(T_ref < 0, -1.0, 1.0);  // not a branch: either sign at random
    const OperatingLimits L{sign * lim.omega, lim.V_max, lim.I_max};
    const double kT = kT_;
    const double T_red = std::abs(T_ref) * inv_kT_;

    CurrentCommand cmd;
    // MTPA at I_max decides between the MTPA region and field weakening and enters the base-torque
    // estimate: kept while the machine and the current limit stay, it is known at once (and so is
    // the branch on it).
    if (!(L.I_max == I_max_ && m.psi_m == psi_m_ && m.L_d == L_d_ && m.L_q == L_q_)) {
        p1_ = mtpa_at_current(m, L.I_max);
        psi_m_ = m.psi_m, L_d_ = m.L_d, L_q_ = m.L_q, I_max_ = L.I_max;
    }
    const Point p1 = p1_;
    const double v1 = voltage_sq(m, L.omega, p1.i_d, p1.i_q);
    Limit top;
    Point p{0.0, 0.0};
    if (v1 > voltage_limit_sq(L) && T_red > 0 && field_weakening_fast(m, L, T_red, v1, top, p, cmd.region)) {
        // done: T_max by Halley's method, the command by one Ferrari solution
    } else {
        // The sequential path: below the base speed, zero torque, non-salient machines, and
        // whenever a prediction or check of the fast path failed.
        top = max_torque_from(m, L, p1, v1);
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
        } else if (T_red <= top.T_base) {
            // Below the base speed for this torque side, or a torque low enough for MTPA at this
            // speed (predicted): MTPA first (seed Case i), Case ii if its voltage is too high.
            p = mtpa(m, T_red);
            cmd.region = Region::mtpa;
            if (voltage_sq(m, L.omega, p.i_d, p.i_q) > voltage_limit_sq(L)) {
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
                if (within_voltage(m, L, q)) {
                    p = q;
                    cmd.region = Region::mtpa;
                }
            }
        }
    }
    cmd.torque_max = top.T_red * kT;
    cmd.i_d = p.i_d;
    cmd.i_q = sign * p.i_q;
    cmd.torque = kT * reduced_torque(m, cmd.i_d, cmd.i_q);
    return cmd;
}

CurrentCommand optimal_current(const LinearMachine& m, int pole_pairs, double T_ref, const OperatingLimits& lim) {
    return CommandSolver(pole_pairs)(m, T_ref, lim);
}

}  // namespace ipmsm::linear
