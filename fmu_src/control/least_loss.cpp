#include "control/least_loss.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include "control/level_search.hpp"

namespace ipmsm {
namespace {

double sign_of(double T) { return T < 0 ? -1.0 : 1.0; }

// The least |psi|^2 between a circle's samples is taken as this share of the least sampled (the
// flux varies smoothly along a circle of 128 samples; a bound for skipping circles, not a result).
constexpr double kFluxMargin = 0.8;

// The shaft-torque bounds of a stretch of circle samples widened by this share of their terms'
// magnitudes (the products |psi_d i_q|, |psi_q i_d|, |shift i_q| and the drag, not their sum,
// which can cancel): the bounds and the samples' torques are the same sums in another order,
// whose rounding differs by a few units in the last place of those terms.
constexpr double kStretchBoundMargin = 1e-12;

// A scalar field's value, gradient and Hessian at one point.
struct Field {
    double v = 0, d = 0, q = 0, dd = 0, dq = 0, qq = 0;
};
Field operator*(double k, const Field& a) { return {k * a.v, k * a.d, k * a.q, k * a.dd, k * a.dq, k * a.qq}; }
Field operator+(const Field& a, const Field& b) {
    return {a.v + b.v, a.d + b.d, a.q + b.q, a.dd + b.dd, a.dq + b.dq, a.qq + b.qq};
}

// The problem at one operating condition. On the curve T_shaft = T* the inverter's P_ac term is
// k_ac (T* w_m + P_fe + P_cu), so the loss there is, up to the constant k_ac T* w_m,
//     J = a |i|^2 + b |i| + e P_fe,   a = 1.5 R (1 + k_ac) + k_square,  b = k_linear,  e = 1 + k_ac
// (docs/spec/MATH.md, "Least-loss control": the same stationary points as the full loss).
struct Problem {
    double kT;     // 1.5 p
    double w_m;    // rad/s
    double omega;  // electrical, rad/s
    double R;      // Ohm
    double V2, I2;
    double a, b, e;
    double f;  // Hz, iron-loss frequency (0 at standstill)
    const IronLossModel* iron;
    double shift;  // the magnets' psi_d shift, Wb

    Problem(const OperatingLimits& lim, const MagnetFlux& flux, const DriveLoss& loss, int pole_pairs)
        : kT(torque_factor(pole_pairs)),
          w_m(loss.w_m()),
          omega(lim.omega),
          R(loss.R()),
          V2(lim.V_max * lim.V_max),
          I2(lim.I_max * lim.I_max),
          a(1.5 * loss.R() * (1.0 + loss.inverter().k_ac()) + loss.inverter().k_square()),
          b(loss.inverter().k_linear()),
          e(1.0 + loss.inverter().k_ac()),
          f(loss.frequency()),
          iron(&loss.iron()),
          shift(flux.shift()) {}

    double drag(double P_fe) const { return w_m != 0.0 ? P_fe / w_m : 0.0; }
    double P_fe(double s) const { return f > 0.0 ? iron->power_at(f, s) : 0.0; }
};

struct Fields {
    Field h;  // shaft torque, N.m
    Field J;  // the loss on the curve (above), W
    Field g;  // |v|^2
    Field c;  // |i|^2
};

Fields fields_at(const MagnetFlux& flux, const Problem& P, double i_d, double i_q) {
    const FluxPoint2 f = flux.eval2(i_d, i_q);
    Field T;  // T' = psi_d i_q - psi_q i_d
    T.v = f.psi_d * i_q - f.psi_q * i_d;
    T.d = f.L_dd * i_q - f.L_qd * i_d - f.psi_q;
    T.q = f.L_dq * i_q + f.psi_d - f.L_qq * i_d;
    T.dd = f.psi_d_dd * i_q - f.psi_q_dd * i_d - 2.0 * f.L_qd;
    T.dq = f.psi_d_dq * i_q + f.L_dd - f.psi_q_dq * i_d - f.L_qq;
    T.qq = f.psi_d_qq * i_q + 2.0 * f.L_dq - f.psi_q_qq * i_d;
    Field s;  // |psi|^2
    s.v = f.psi_d * f.psi_d + f.psi_q * f.psi_q;
    s.d = 2.0 * (f.psi_d * f.L_dd + f.psi_q * f.L_qd);
    s.q = 2.0 * (f.psi_d * f.L_dq + f.psi_q * f.L_qq);
    s.dd = 2.0 * (f.L_dd * f.L_dd + f.L_qd * f.L_qd + f.psi_d * f.psi_d_dd + f.psi_q * f.psi_q_dd);
    s.dq = 2.0 * (f.L_dd * f.L_dq + f.L_qd * f.L_qq + f.psi_d * f.psi_d_dq + f.psi_q * f.psi_q_dq);
    s.qq = 2.0 * (f.L_dq * f.L_dq + f.L_qq * f.L_qq + f.psi_d * f.psi_d_qq + f.psi_q * f.psi_q_qq);
    Field Pfe;
    if (P.f > 0.0) {
        const IronLossAtFlux D = P.iron->derivatives_at(P.f, s.v);
        Pfe = {D.P,
               D.dP * s.d,
               D.dP * s.q,
               D.d2P * s.d * s.d + D.dP * s.dd,
               D.d2P * s.d * s.q + D.dP * s.dq,
               D.d2P * s.q * s.q + D.dP * s.qq};
    }
    Fields F;
    F.h = P.kT * T + (P.w_m != 0.0 ? -1.0 / P.w_m : 0.0) * Pfe;
    F.c = {i_d * i_d + i_q * i_q, 2.0 * i_d, 2.0 * i_q, 2.0, 0.0, 2.0};
    Field r;  // |i|, smooth away from 0
    r.v = std::sqrt(F.c.v);
    if (r.v > 0.0) {
        r.d = i_d / r.v, r.q = i_q / r.v;
        const double k = 1.0 / (F.c.v * r.v);
        r.dd = i_q * i_q * k, r.dq = -i_d * i_q * k, r.qq = i_d * i_d * k;
    }
    F.J = P.a * F.c + P.b * r + P.e * Pfe;
    const double w = P.omega, R = P.R;
    const double vd = R * i_d - w * f.psi_q, vq = R * i_q + w * f.psi_d;
    const double j00 = R - w * f.L_qd, j01 = -w * f.L_qq, j10 = w * f.L_dd, j11 = R + w * f.L_dq;
    F.g.v = vd * vd + vq * vq;
    F.g.d = 2.0 * (vd * j00 + vq * j10);
    F.g.q = 2.0 * (vd * j01 + vq * j11);
    F.g.dd = 2.0 * (j00 * j00 + j10 * j10 + w * (vq * f.psi_d_dd - vd * f.psi_q_dd));
    F.g.dq = 2.0 * (j00 * j01 + j10 * j11 + w * (vq * f.psi_d_dq - vd * f.psi_q_dq));
    F.g.qq = 2.0 * (j01 * j01 + j11 * j11 + w * (vq * f.psi_d_qq - vd * f.psi_q_qq));
    return F;
}

// One equation: value and gradient.
struct Eq {
    double v, d, q;
};
Eq level(const Field& a, double target) { return {a.v - target, a.d, a.q}; }
// (grad a x grad b), zero where the level curves of a and b touch (Lagrange).
Eq cross(const Field& a, const Field& b) {
    return {a.d * b.q - a.q * b.d, a.dd * b.q + a.d * b.dq - a.dq * b.d - a.q * b.dd,
            a.dq * b.q + a.d * b.qq - a.qq * b.d - a.q * b.dq};
}

enum class System {
    interior,     // grad J x grad h = 0, h = T*
    voltage,      // |v| = V_max, h = T*
    current,      // |i| = I_max, h = T*
    top_current,  // |i| = I_max, grad h x grad c = 0
    top_voltage,  // |v| = V_max, grad h x grad g = 0
    top_corner,   // |i| = I_max, |v| = V_max
};

struct Point {
    double i_d = 0, i_q = 0;
    bool converged = false;
    int iterations = 0;
};

Point newton(const MagnetFlux& flux, const Problem& P, System sys, double T, double i_d, double i_q, double I_max,
             int max_iterations = 40) {
    const double tol = 1e-10 * I_max, max_step = 0.1 * I_max;
    Point p{i_d, i_q, false, 0};
    for (int k = 0; k < max_iterations; ++k) {
        const Fields F = fields_at(flux, P, p.i_d, p.i_q);
        ++p.iterations;
        Eq e1{}, e2{};
        switch (sys) {
            case System::interior: e1 = cross(F.J, F.h), e2 = level(F.h, T); break;
            case System::voltage: e1 = level(F.g, P.V2), e2 = level(F.h, T); break;
            case System::current: e1 = level(F.c, P.I2), e2 = level(F.h, T); break;
            case System::top_current: e1 = level(F.c, P.I2), e2 = cross(F.h, F.c); break;
            case System::top_voltage: e1 = level(F.g, P.V2), e2 = cross(F.h, F.g); break;
            case System::top_corner: e1 = level(F.c, P.I2), e2 = level(F.g, P.V2); break;
        }
        const double det = e1.d * e2.q - e1.q * e2.d;
        if (!(std::abs(det) > 0.0) || !std::isfinite(det)) return p;
        double dd = (-e1.v * e2.q + e2.v * e1.q) / det;
        double dq = (-e2.v * e1.d + e1.v * e2.d) / det;
        const double step = std::hypot(dd, dq);
        if (!std::isfinite(step)) return p;
        if (step > max_step) dd *= max_step / step, dq *= max_step / step;
        p.i_d += dd;
        p.i_q += dq;
        if (step <= tol) {
            p.converged = true;
            return p;
        }
    }
    return p;
}

// A point and what matters of it, from the map's first derivatives only.
struct Eval {
    double h, J, g, c;
};
// At the currents (i_d, i_q) whose fluxes are f.
Eval evaluate_at(const FluxPoint& f, const Problem& P, double i_d, double i_q) {
    const double s = f.psi_d * f.psi_d + f.psi_q * f.psi_q;
    const double Pfe = P.P_fe(s);
    const double c = i_d * i_d + i_q * i_q;
    const double vd = P.R * i_d - P.omega * f.psi_q, vq = P.R * i_q + P.omega * f.psi_d;
    return {P.kT * (f.psi_d * i_q - f.psi_q * i_d) - P.drag(Pfe), P.a * c + P.b * std::sqrt(c) + P.e * Pfe,
            vd * vd + vq * vq, c};
}
Eval evaluate(const MagnetFlux& flux, const Problem& P, double i_d, double i_q) {
    return evaluate_at(flux.eval(i_d, i_q), P, i_d, i_q);
}

// A sampled crossing of the curve h = T*: a seed.
struct Crossing {
    double i_d, i_q, J;
    bool voltage_near;  // one of its samples breaks the voltage limit
};

// The best few crossings, apart from each other (distinct stretches of the curve).
struct Seeds {
    static constexpr int kMax = 4;
    Crossing c[kMax];
    int n = 0;
    double apart2 = 0;  // squared distance below which two crossings are the same stretch
    void offer(const Crossing& x) {
        for (int k = 0; k < n; ++k) {
            const double dd = c[k].i_d - x.i_d, dq = c[k].i_q - x.i_q;
            if (dd * dd + dq * dq < apart2) {
                if (x.J < c[k].J) {
                    c[k] = x;
                    sort();
                }
                return;
            }
        }
        if (n < kMax) {
            c[n++] = x;
        } else if (x.J < c[n - 1].J) {
            c[n - 1] = x;
        } else {
            return;
        }
        sort();
    }
    void sort() {  // insertion sort of at most kMax
        for (int i = 1; i < n; ++i)
            for (int j = i; j > 0 && c[j].J < c[j - 1].J; --j) std::swap(c[j], c[j - 1]);
    }
    double best() const { return n > 0 ? c[0].J : INFINITY; }
};

// One sample of the scan.
struct Sample {
    double i_d, i_q, h, J;
    bool feasible;
};

// A sample of the current circles at the problem's magnet shift: its shaft torque, its loss on
// the curve (lin: the circle's a r^2 + b r) and whether it holds the voltage limit (V2_ok).
Sample sampled(const CurrentCircles::Sample& x, const Problem& P, double lin, double V2_ok) {
    const double psi_d = x.psi_d + P.shift;
    const double Pfe = P.P_fe(psi_d * psi_d + x.psi_q * x.psi_q);
    const double vd = P.R * x.i_d - P.omega * x.psi_q, vq = P.R * x.i_q + P.omega * psi_d;
    return {x.i_d, x.i_q, P.kT * (psi_d * x.i_q - x.psi_q * x.i_d) - P.drag(Pfe), lin + P.e * Pfe,
            vd * vd + vq * vq <= V2_ok};
}

// T_max's candidates on the current circle |i| = I_max polished while their sampled estimate is
// within this of the best polished shaft torque (as least current's, saturated_optimal_current.cpp:
// an estimate is off by the torque's curvature over a sample).
constexpr double kTopCandidateMargin = 0.01;

// The walk along the curve about the best polished point: steps of this fraction of the map's
// grid spacing, this many to each side (two circle samples' reach on the Prius map's 10 A grid).
constexpr double kCurveStepFraction = 0.125;
constexpr int kCurveSteps = 16;

}  // namespace

LeastLoss::LeastLoss(std::shared_ptr<const FluxMap> map, int pole_pairs, bool magnet_free)
    : map_(std::move(map)),
      resolution_(level_search::grid_resolution(*map_)),
      pole_pairs_(pole_pairs),
      magnet_free_(magnet_free) {}

const CurrentCircles& LeastLoss::circles(double I_max) {
    if (!circles_ || circles_->I_max() != I_max) circles_ = std::make_shared<const CurrentCircles>(*map_, I_max);
    return *circles_;
}

const std::vector<double>& LeastLoss::least_flux_sq(const CurrentCircles& C, double shift) {
    const double rounded = std::round(shift / kShiftStep) * kShiftStep;
    if (psi2_shift_ == rounded && psi2_min_.size() == CurrentCircles::kRadii && psi2_circles_ == &C) return psi2_min_;
    psi2_min_.assign(CurrentCircles::kRadii, INFINITY);
    for (int k = 1; k <= CurrentCircles::kRadii; ++k)
        for (int j = 0; j < CurrentCircles::kAngles; ++j) {
            const CurrentCircles::Sample& x = C.at(k, j);
            // any shift within kShiftStep of the rounded one
            const double d = std::max(0.0, std::abs(x.psi_d + rounded) - kShiftStep);
            psi2_min_[k - 1] = std::min(psi2_min_[k - 1], d * d + x.psi_q * x.psi_q);
        }
    psi2_shift_ = rounded;
    psi2_circles_ = &C;
    return psi2_min_;
}

LeastLoss::Interval LeastLoss::drag_bounds(const CurrentCircles::Arc& circle, double shift, const IronLossModel& iron,
                                           double f, double w_m) {
    if (!(f > 0.0) || w_m == 0.0) return {0.0, 0.0};
    const double a = iron.power_at(f, circle.flux_sq_lo(shift)) / w_m;
    const double b = iron.power_at(f, circle.flux_sq_hi(shift)) / w_m;
    return {std::min(a, b), std::max(a, b)};
}

LeastLoss::Interval LeastLoss::stretch_torque_bounds(const CurrentCircles::Arc& stretch, double kT, double shift,
                                                     const Interval& drag) {
    const double lo = kT * stretch.torque_lo_at(shift) - drag.hi, hi = kT * stretch.torque_hi_at(shift) - drag.lo;
    const double margin =
        kStretchBoundMargin * (kT * (stretch.terms + std::abs(stretch.torque_lo) + std::abs(stretch.torque_hi) +
                                     std::abs(shift) * (std::abs(stretch.i_q_lo) + std::abs(stretch.i_q_hi))) +
                               std::abs(drag.lo) + std::abs(drag.hi));
    return {lo - margin, hi + margin};
}

LossSplit LeastLoss::loss_at(const MagnetFlux& flux, const DriveLoss& loss, int pole_pairs, double i_d, double i_q) {
    const FluxPoint f = flux.eval(i_d, i_q);
    const double T_e = torque_factor(pole_pairs) * (f.psi_d * i_q - f.psi_q * i_d);
    return loss.at(i_d, i_q, f.psi_d, f.psi_q, T_e);
}

LeastLossResult LeastLoss::solve(double T_ref, const OperatingLimits& lim, const MagnetFlux& flux,
                                 const DriveLoss& loss, const CurrentCommand& em_top, const CurrentPoint* hint) {
    const Problem P(lim, flux, loss, pole_pairs_);
    const CurrentCircles& C = circles(lim.I_max);
    const double s = sign_of(T_ref);
    const double V2_ok = P.V2 * (1.0 + 1e-9), I2_ok = P.I2 * (1.0 + 1e-9);
    LeastLossResult out;
    int evaluations = 0;
    auto finish = [&](CurrentCommand cmd, double T_max) {
        if (magnet_free_ && cmd.i_d > 0.0) {  // the mirror ties on a magnet-free map: i_d <= 0
            const Eval a = evaluate(flux, P, cmd.i_d, cmd.i_q), b = evaluate(flux, P, -cmd.i_d, -cmd.i_q);
            if (std::abs(a.h - b.h) <= 1e-9 * std::max(1.0, T_max) && std::abs(a.J - b.J) <= 1e-9 * a.J && b.g <= V2_ok)
                cmd.i_d = -cmd.i_d, cmd.i_q = -cmd.i_q;
        }
        cmd.torque_max = std::max(0.0, T_max);
        cmd.torque = evaluate(flux, P, cmd.i_d, cmd.i_q).h;
        cmd.iterations = evaluations;
        out.cmd = cmd;
        out.loss = loss_at(flux, loss, pole_pairs_, cmd.i_d, cmd.i_q);
        out.evaluations = evaluations;
        return out;
    };

    // ---- 1. T_max: the most shaft torque s h within the limits.
    auto feasible = [&](double i_d, double i_q, Eval& e) {
        e = evaluate(flux, P, i_d, i_q);
        ++evaluations;
        return e.c <= I2_ok && e.g <= V2_ok;
    };
    // Is p a local maximum of s h for the system's active limits (KKT multipliers' signs)?
    auto top_kkt = [&](System sys, const Point& p) {
        const Fields F = fields_at(flux, P, p.i_d, p.i_q);
        const double hd = s * F.h.d, hq = s * F.h.q;
        const double tol = 1e-6;
        switch (sys) {
            case System::top_current:
                return hd * F.c.d + hq * F.c.q >= -tol * std::hypot(hd, hq) * std::hypot(F.c.d, F.c.q);
            case System::top_voltage:
                return hd * F.g.d + hq * F.g.q >= -tol * std::hypot(hd, hq) * std::hypot(F.g.d, F.g.q);
            case System::top_corner: {
                const double det = F.c.d * F.g.q - F.c.q * F.g.d;
                if (det == 0.0) return false;
                const double lambda = (hd * F.g.q - hq * F.g.d) / det, mu = (F.c.d * hq - F.c.q * hd) / det;
                const double scale = std::hypot(hd, hq);
                return lambda * std::hypot(F.c.d, F.c.q) >= -tol * scale &&
                       mu * std::hypot(F.g.d, F.g.q) >= -tol * scale;
            }
            default: return false;
        }
    };
    struct Top {
        Point p;
        double H = -INFINITY;
        Region region = Region::mtpa;
    } top;
    auto try_system = [&](System sys, double i_d, double i_q, bool need_kkt) {
        const Point p = newton(flux, P, sys, 0.0, i_d, i_q, lim.I_max);
        evaluations += p.iterations;
        Eval e{};
        if (!p.converged || !feasible(p.i_d, p.i_q, e)) return;
        if (magnet_free_ && p.i_d > 1e-9 * lim.I_max) return;
        if (need_kkt && !top_kkt(sys, p)) return;
        if (s * e.h > top.H) {
            top.p = p;
            top.H = s * e.h;
            top.region = sys == System::top_current   ? Region::mtpa
                         : sys == System::top_voltage ? Region::mtpv
                                                      : Region::current_and_voltage_limit;
        }
    };
    auto try_top = [&](double i_d, double i_q, bool need_kkt) {
        for (System sys : {System::top_current, System::top_voltage, System::top_corner})
            try_system(sys, i_d, i_q, need_kkt);
    };
    Eval e_top{};
    const bool em_feasible = em_top.feasible && feasible(em_top.i_d, em_top.i_q, e_top);
    if (em_feasible) try_top(em_top.i_d, em_top.i_q, true);
    // The shaft torque along the current circle within the voltage limit, from its samples: on a
    // map whose torque along the circle has two maxima of nearly equal height (a measured map's
    // ripple), the drag can make another one than the electromagnetic torque's the largest, and
    // two maxima can lie between the same samples' neighbours (the Prius map's, 1.5 samples
    // apart). Newton on the circle from every sample within the limit whose shaft torque comes
    // within kTopCandidateMargin of the best found, and on the corner from where the circle
    // crosses the voltage limit; each result a local maximum (KKT), the most torque wins.
    {
        constexpr int K = CurrentCircles::kRadii, N = CurrentCircles::kAngles;
        Sample x[N];
        double best_sample = -INFINITY;
        for (int j = 0; j < N; ++j) {
            x[j] = sampled(C.at(K, j), P, 0.0, V2_ok), x[j].h *= s;
            if (magnet_free_ && x[j].i_d > 0.0) x[j].feasible = false;
            if (x[j].feasible) best_sample = std::max(best_sample, x[j].h);
        }
        evaluations += N;
        for (int j = 0; j < N; ++j) {
            const double bar = std::max(top.H, best_sample);
            if (!x[j].feasible || x[j].h < bar - kTopCandidateMargin * std::abs(bar)) continue;
            try_system(System::top_current, x[j].i_d, x[j].i_q, true);
            for (const Sample* o : {&x[(j + N - 1) % N], &x[(j + 1) % N]})
                if (!o->feasible) try_top(0.5 * (x[j].i_d + o->i_d), 0.5 * (x[j].i_q + o->i_q), true);
        }
    }
    // The robust search where no local maximum came from the seed, or it is below the seed itself.
    if (!(top.H >= (em_feasible ? s * e_top.h : -INFINITY) - kTorqueTolerance * std::abs(e_top.h))) {
        out.searched = true;
        double best = -INFINITY;
        double bd = 0, bq = 0;
        for (int k = 1; k <= CurrentCircles::kRadii; ++k)
            for (int j = 0; j < CurrentCircles::kAngles; ++j) {
                const CurrentCircles::Sample& x = C.at(k, j);
                if (magnet_free_ && x.i_d > 0) continue;
                Eval e{};
                if (!feasible(x.i_d, x.i_q, e)) continue;
                if (s * e.h > best) best = s * e.h, bd = x.i_d, bq = x.i_q;
            }
        if (best > -INFINITY) {
            try_top(bd, bq, false);
            if (!(top.H >= best)) top.p = {bd, bq, true, 0}, top.H = best, top.region = Region::mtpa;
        } else if (em_feasible) {
            top.p = {em_top.i_d, em_top.i_q, true, 0}, top.H = s * e_top.h, top.region = em_top.region;
        }
    }
    if (!(top.H > -INFINITY)) {  // nothing within both limits: above the maximum speed
        CurrentCommand cmd = em_top;
        cmd.feasible = false;
        out.check_passed = em_top.feasible;
        return finish(cmd, 0.0);
    }
    CurrentCommand at_top;
    at_top.i_d = top.p.i_d, at_top.i_q = top.p.i_q, at_top.region = top.region, at_top.feasible = true;
    if (std::abs(T_ref) >= top.H) return finish(at_top, top.H);

    // ---- 2. Below T_max: the least loss on the curve h = T_ref.
    const double T = T_ref;
    Seeds seeds;
    const double spacing = lim.I_max * 2.0 * kPi / CurrentCircles::kAngles;
    seeds.apart2 = 4.0 * spacing * spacing;
    // Polished points: the best of them is the command.
    struct Best {
        Point p;
        double J = INFINITY;
        Region region = Region::mtpa;
    } best;
    auto consider = [&](const Point& p, System sys) {
        evaluations += p.iterations;
        Eval e{};
        if (!p.converged || !feasible(p.i_d, p.i_q, e)) return false;
        if (std::abs(e.h - T) > kTorqueTolerance * std::max(top.H, 1.0)) return false;
        if (magnet_free_ && p.i_d > 1e-9 * lim.I_max) return false;
        if (e.J < best.J)
            best.p = p, best.J = e.J,
            best.region = sys == System::voltage   ? Region::voltage_limit
                          : sys == System::current ? Region::current_and_voltage_limit
                                                   : Region::mtpa;
        return true;
    };
    const double rim2 = P.I2 * (1.0 - 2.0 / CurrentCircles::kRadii) * (1.0 - 2.0 / CurrentCircles::kRadii);
    // The hint first (the least-current command for T*, near the least loss at low speed): its
    // exact loss bounds the scan from the start.
    if (hint != nullptr && std::isfinite(hint->i_d) && std::isfinite(hint->i_q)) {
        if (!consider(newton(flux, P, System::interior, T, hint->i_d, hint->i_q, lim.I_max), System::interior))
            consider(newton(flux, P, System::voltage, T, hint->i_d, hint->i_q, lim.I_max), System::voltage);
    }
    // A lower bound of J on a circle of radius r: a r^2 + b r + e P_fe(the least |psi|^2 sampled on
    // it, less a margin for between the samples).
    const std::vector<double>& psi2_min = least_flux_sq(C, P.shift);
    constexpr int N = CurrentCircles::kAngles, L = CurrentCircles::kArc, M = CurrentCircles::kArcs;
    // prev: circle k - 1 (its samples computed where a stretch needed them: prev_done), cur: circle k.
    Sample rows[2][N];
    bool rows_done[2][N];
    Sample *prev = rows[0], *cur = rows[1];
    bool *prev_done = rows_done[0], *cur_done = rows_done[1];
    bool prev_scanned = true;  // circle k - 1 was scanned (not skipped by its loss bound)
    double bounds[2][2][M];    // each stretch's shaft-torque bounds, lo and hi, of circles k - 1 and k
    double *prev_lo = bounds[0][0], *prev_hi = bounds[0][1], *cur_lo = bounds[1][0], *cur_hi = bounds[1][1];
    {
        Eval e{};
        const bool ok = feasible(0.0, 0.0, e);
        for (int j = 0; j < N; ++j) prev[j] = {0.0, 0.0, e.h, e.J, ok}, prev_done[j] = true;
        for (int m = 0; m < M; ++m) prev_lo[m] = prev_hi[m] = e.h;
    }
    auto offer = [&](const Sample& x, const Sample& y) {
        const double fx = x.h - T, fy = y.h - T;
        if (!((fx <= 0.0 && fy >= 0.0) || (fx >= 0.0 && fy <= 0.0)) || fx == fy) return;
        if (!x.feasible && !y.feasible) return;
        const double t = fx / (fx - fy);
        Crossing c{x.i_d + t * (y.i_d - x.i_d), x.i_q + t * (y.i_q - x.i_q), x.J + t * (y.J - x.J),
                   !(x.feasible && y.feasible)};
        if (magnet_free_ && c.i_d > 0.0) return;
        seeds.offer(c);
    };
    // Stretches are skipped by their shaft-torque bounds where the iron loss grows with the flux.
    const bool prune = !reference_scan_ && P.iron->k_h >= 0.0 && P.iron->k_e >= 0.0 && P.iron->alpha > 0.0;
    for (int k = 1; k <= CurrentCircles::kRadii; ++k) {
        const double r_in = C.radius(k - 1);
        // no point beyond r_in loses less than its copper and inverter loss alone; on circle k (and
        // between k - 1 and k) no less than that bound with the circle's least iron loss
        const double bound = std::min(seeds.best() * 1.25, best.J);
        if (P.a * r_in * r_in + P.b * r_in > bound) break;
        const double psi2 = std::min(psi2_min[k - 1], k >= 2 ? psi2_min[k - 2] : psi2_min[k - 1]);
        if (P.a * r_in * r_in + P.b * r_in + P.e * P.P_fe(kFluxMargin * psi2) > bound) {
            prev_scanned = false;
            continue;
        }
        const double r = C.radius(k), lin = P.a * r * r + P.b * r;
        // Each stretch's samples have their shaft torque within its bounds (MATH.md): a stretch of
        // both circles whose bounds exclude T* has no crossing on its rays and arcs, and its
        // samples are not needed.
        const Interval drag = prune ? drag_bounds(C.whole(k), P.shift, *P.iron, P.f, P.w_m) : Interval{};
        for (int m = 0; m < M; ++m) {
            Interval h{-INFINITY, INFINITY};
            if (prune) {
                h = stretch_torque_bounds(C.arc(k, m), P.kT, P.shift, drag);
                // the stretch's own drag bounds, tighter, where the circle's do not exclude T*
                if (h.lo <= T && T <= h.hi)
                    h = stretch_torque_bounds(C.arc(k, m), P.kT, P.shift,
                                              drag_bounds(C.arc(k, m), P.shift, *P.iron, P.f, P.w_m));
            }
            cur_lo[m] = h.lo, cur_hi[m] = h.hi;
        }
        std::fill(cur_done, cur_done + N, false);
        auto need = [&](Sample* row, bool* done, int kk, int j) {
            if (done[j]) return;
            row[j] =
                sampled(C.at(kk, j), P, kk == k ? lin : P.a * C.radius(kk) * C.radius(kk) + P.b * C.radius(kk), V2_ok);
            done[j] = true;
            ++evaluations;
        };
        for (int m = 0; m < M; ++m) {
            // T* outside the hull of both circles' bounds: no ray or arc of the stretch crosses it
            // (a NaN bound on either circle: scanned; std::min would drop it)
            double lo = cur_lo[m], hi = cur_hi[m];
            if (prev_scanned) {
                if (std::isnan(prev_lo[m]) || std::isnan(prev_hi[m])) lo = hi = NAN;
                lo = std::min(lo, prev_lo[m]), hi = std::max(hi, prev_hi[m]);
            }
            if (lo > T || hi < T) continue;
            for (int j = m * L; j <= (m + 1) * L; ++j) {
                const int jj = j % N;
                need(cur, cur_done, k, jj);
                if (prev_scanned) need(prev, prev_done, k - 1, jj);
            }
            for (int j = m * L; j < (m + 1) * L; ++j) {
                if (prev_scanned) offer(prev[j], cur[j]);
                offer(cur[j], cur[(j + 1) % N]);
            }
        }
        std::swap(prev, cur), std::swap(prev_done, cur_done), std::swap(prev_lo, cur_lo), std::swap(prev_hi, cur_hi);
        prev_scanned = true;
    }

    // Polish each seed: the interior stationary point, else the curve on the limit it breaks.
    for (int n = 0; n < seeds.n; ++n) {
        const Crossing& x = seeds.c[n];
        if (x.J > 1.25 * best.J) continue;  // (interpolated: a margin for its error)
        const Point p = newton(flux, P, System::interior, T, x.i_d, x.i_q, lim.I_max);
        Eval e{};
        const bool interior_ok = p.converged && feasible(p.i_d, p.i_q, e);
        // Newton also finds stationary points that are maxima of the loss along the curve: keep
        // only one no worse than its seed's neighbourhood (the crossings' loss is interpolated,
        // so within the interpolation's error)
        if (interior_ok) consider(p, System::interior);
        if (!interior_ok || x.voltage_near)
            consider(newton(flux, P, System::voltage, T, x.i_d, x.i_q, lim.I_max), System::voltage);
        if (!interior_ok || x.i_d * x.i_d + x.i_q * x.i_q >= rim2)
            consider(newton(flux, P, System::current, T, x.i_d, x.i_q, lim.I_max), System::current);
    }
    // Near T_max the curve's stretch within the limits is short and ends on them: from T_max's point too.
    if (!(best.J < INFINITY) || std::abs(T) > 0.9 * top.H) {
        consider(newton(flux, P, System::current, T, top.p.i_d, top.p.i_q, lim.I_max), System::current);
        consider(newton(flux, P, System::voltage, T, top.p.i_d, top.p.i_q, lim.I_max), System::voltage);
        consider(newton(flux, P, System::interior, T, top.p.i_d, top.p.i_q, lim.I_max), System::interior);
    }
    // Along the curve about the best point, at a fraction of the map's grid spacing: where the
    // loss along the curve ripples (a spline over a coarse grid), two local minima can lie within
    // one crossing's reach, and Newton from it finds either (the published Prius map at 900 r/min,
    // 238 N.m: 4.7 A and 0.07 % apart). A predictor-corrector walk (a step along the curve's
    // tangent, Newton's correction of the torque); a point that loses less seeds Newton.
    if (best.J < INFINITY) {
        const Point from = best.p;
        const double step = kCurveStepFraction * resolution_;
        double lowest = best.J, ld = 0, lq = 0;
        for (double side : {-1.0, 1.0}) {
            double i_d = from.i_d, i_q = from.i_q;
            for (int n = 0; n < kCurveSteps; ++n) {
                const FluxPoint f = flux.eval(i_d, i_q);
                ++evaluations;
                const Eval e = evaluate_at(f, P, i_d, i_q);
                const double h = e.h;
                const double gd = P.kT * (f.L_dd * i_q - f.L_qd * i_d - f.psi_q);
                const double gq = P.kT * (f.L_dq * i_q + f.psi_d - f.L_qq * i_d);
                const double g2 = gd * gd + gq * gq;
                if (!(g2 > 0.0) || e.c > I2_ok) break;
                if (n > 0 && std::abs(h - T) <= 1e-3 * std::max(top.H, 1.0) && e.J < lowest)
                    lowest = e.J, ld = i_d, lq = i_q;
                const double g = std::sqrt(g2);
                i_d += -(h - T) * gd / g2 - side * step * gq / g;
                i_q += -(h - T) * gq / g2 + side * step * gd / g;
            }
        }
        if (lowest < best.J * (1.0 - kLossTolerance)) {
            if (!consider(newton(flux, P, System::interior, T, ld, lq, lim.I_max), System::interior))
                consider(newton(flux, P, System::voltage, T, ld, lq, lim.I_max), System::voltage);
        }
    }
    // ---- 3. The check: no crossing, projected onto the curve, loses less than the command.
    const double scale = best.J < INFINITY ? std::max(1.0, best.J) : 1.0;
    bool passed = best.J < INFINITY;
    for (int n = 0; n < seeds.n; ++n) {
        // project the crossing onto the curve along grad h (Newton in one dimension)
        double i_d = seeds.c[n].i_d, i_q = seeds.c[n].i_q;
        for (int it = 0; it < 8; ++it) {
            const FluxPoint f = flux.eval(i_d, i_q);
            const double Pfe = P.P_fe(f.psi_d * f.psi_d + f.psi_q * f.psi_q);
            const double h = P.kT * (f.psi_d * i_q - f.psi_q * i_d) - P.drag(Pfe);
            const double gd = P.kT * (f.L_dd * i_q - f.L_qd * i_d - f.psi_q);
            const double gq = P.kT * (f.L_dq * i_q + f.psi_d - f.L_qq * i_d);
            const double g2 = gd * gd + gq * gq;  // (the drag's gradient left out: a small change of direction)
            if (!(g2 > 0.0)) break;
            const double d_next = i_d - (h - T) * gd / g2, q_next = i_q - (h - T) * gq / g2;
            ++evaluations;
            // a step that no longer moves the point: the remaining ones would repeat it exactly
            if (d_next == i_d && q_next == i_q) break;
            i_d = d_next, i_q = q_next;
        }
        Eval e{};
        if (!feasible(i_d, i_q, e) || std::abs(e.h - T) > kTorqueTolerance * std::max(top.H, 1.0)) continue;
        if (!(best.J < INFINITY)) {  // nothing polished: the projected crossing, exact in torque
            passed = false;
            out.searched = true;
            best.p = {i_d, i_q, true, 0}, best.J = e.J, best.region = Region::mtpa;
            continue;
        }
        if (e.J < best.J - kLossTolerance * scale) {
            // the robust replacement: the better crossing, polished where Newton holds from it
            passed = false;
            out.searched = true;
            best.p = {i_d, i_q, true, 0}, best.J = e.J, best.region = Region::mtpa;
            consider(newton(flux, P, System::interior, T, i_d, i_q, lim.I_max), System::interior);
        }
    }
    out.check_passed = passed;
    if (!(best.J < INFINITY)) {
        // no polished point: the best crossing, or T_max's point
        out.check_passed = false;
        if (seeds.n > 0 && !seeds.c[0].voltage_near) {
            CurrentCommand cmd = at_top;
            cmd.i_d = seeds.c[0].i_d, cmd.i_q = seeds.c[0].i_q, cmd.converged = false;
            return finish(cmd, top.H);
        }
        at_top.converged = false;
        return finish(at_top, top.H);
    }
    CurrentCommand cmd;
    cmd.i_d = best.p.i_d, cmd.i_q = best.p.i_q;
    cmd.region = T_ref == 0.0 ? Region::zero_torque : best.region;
    cmd.feasible = true;
    return finish(cmd, top.H);
}

}  // namespace ipmsm
