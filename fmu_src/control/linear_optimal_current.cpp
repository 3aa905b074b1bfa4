#include "control/linear_optimal_current.hpp"

#include <algorithm>
#include <cmath>

#include "control/decision.hpp"
#include "control/linear_conditions.hpp"
#include "numerics/quartic.hpp"

namespace ipmsm::linear {
using namespace conditions;  // the quartic of each condition
namespace {

// Relative slack on the limits, so that a point computed *on* a limit counts as within it.
constexpr double kLimitSlack = 1e-9;

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

bool current_voltage_intersection(const LinearMachine& m, double omega, double V_max, double I, Point& out) {
    const IntersectionQuartic Q(m, omega, V_max, I);
    return Q.point(roots_of(Q.c), out);
}

namespace {

// The linear machine as decision.hpp's View, on the T' >= 0 side (lim already mirrored).
struct LinearView {
    const LinearMachine& m;
    const OperatingLimits& lim;

    double torque(Point p) const { return reduced_torque(m, p.i_d, p.i_q); }
    bool within_voltage(Point p) const { return linear::within_voltage(m, lim, p); }
    bool within_current(Point p) const {
        return p.i_d * p.i_d + p.i_q * p.i_q <= lim.I_max * lim.I_max * (1.0 + kLimitSlack);
    }
    bool mtpa_at_current_limit(Point& p) const {
        p = mtpa_at_current(m, lim.I_max);
        return true;
    }
    bool mtpv(Point& p) const { return linear::mtpv(m, lim.omega, lim.V_max, p) && torque(p) >= 0; }
    bool current_voltage_intersection(Point& p) const {
        return linear::current_voltage_intersection(m, lim.omega, lim.V_max, lim.I_max, p) && torque(p) >= 0;
    }
    bool mtpa(double T_red, Point& p) const {
        p = linear::mtpa(m, T_red);
        return true;
    }
    bool voltage_limit(double T_red, Point& p) const {
        return linear::voltage_limit(m, lim.omega, lim.V_max, T_red, p);
    }
    bool zero_torque(Point& p) const { return linear::zero_torque(m, lim.omega, lim.V_max, p); }
};

}  // namespace

Limit max_torque(const LinearMachine& m, const OperatingLimits& lim) {
    LinearView view{m, lim};
    const decision::Choice top = decision::max_torque(view);
    if (!top.feasible) return {{-lim.I_max, 0.0}, 0.0, Region::zero_torque, false};
    return {top.point, view.torque(top.point), top.region, true};
}

CommandSolver::CommandSolver(int pole_pairs) : kT_(torque_factor(pole_pairs)) {}

CurrentCommand CommandSolver::operator()(const LinearMachine& m, double T_ref, const OperatingLimits& lim) const {
    // Mirror negative torque onto positive: (T, omega, i_q) -> (-T, -omega, -i_q).
    const double sign = T_ref < 0 ? -1.0 : 1.0;
    const OperatingLimits L{sign * lim.omega, lim.V_max, lim.I_max};
    LinearView view{m, L};
    const Limit top = max_torque(m, L);
    const decision::Choice c = decision::command(view, std::abs(T_ref) / kT_, {top.point, top.region, top.feasible});
    CurrentCommand cmd;
    cmd.i_d = c.point.i_d;
    cmd.i_q = sign * c.point.i_q;
    cmd.region = c.region;
    cmd.feasible = c.feasible;
    cmd.torque_max = top.T_red * kT_;
    cmd.torque = kT_ * reduced_torque(m, cmd.i_d, cmd.i_q);
    return cmd;
}

CurrentCommand optimal_current(const LinearMachine& m, int pole_pairs, double T_ref, const OperatingLimits& lim) {
    return CommandSolver(pole_pairs)(m, T_ref, lim);
}

}  // namespace ipmsm::linear
