#include "control/saturated_optimal_current.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "control/current_circles.hpp"
#include "control/decision.hpp"
#include "control/fault_injection.hpp"
#include "control/level_search.hpp"
#include "control/map_newton.hpp"
#include "control/max_torque_search.hpp"

namespace ipmsm {
namespace {

// Below this current an apparent inductance (flux / current) is ill-defined: use the incremental one.
constexpr double kApparentMinCurrent_A = 1e-3;
// Relative slack on the limits for points computed on a limit.
constexpr double kLimitSlack = 1e-9;
// A magnet-free machine's command at i_d above this (relative to I_max) is off the convention's branch.
constexpr double kBranchTolerance = 1e-9;

double sign_of(double T) { return T < 0 ? -1.0 : 1.0; }

}  // namespace

void check_current_limit_within_map(const FluxMap& map, double I_max) {
    const double reach = std::min({-map.i_d_min(), -map.i_q_min(), map.i_q_max()});
    if (I_max <= reach) return;
    std::ostringstream os;
    os << "I_max = " << I_max << " A reaches beyond the flux map's grid, which covers currents up to " << reach
       << " A (i_d from " << map.i_d_min() << " A, i_q from " << map.i_q_min() << " to " << map.i_q_max()
       << " A): lower I_max or extend the map";
    throw std::invalid_argument(os.str());
}

const char* describe(CheckFinding f) {
    switch (f) {
        case CheckFinding::passed: return "passed";
        case CheckFinding::torque: return "its torque on the map is not T_cmd";
        case CheckFinding::current_limit: return "its current is above I_max";
        case CheckFinding::voltage_limit: return "its voltage is above V_max";
        case CheckFinding::not_least_current: return "a point of less current makes the torque within the limits";
        case CheckFinding::torque_max: return "its T_max is not the map's";
        case CheckFinding::not_finite: return "it is not finite";
        case CheckFinding::not_least_loss:
            return "a point of the shaft-torque curve within the limits loses less (least loss)";
        case CheckFinding::branch:
            return "i_d > 0 on a magnet-free machine, whose optima tie in mirror pairs: the convention is i_d <= 0";
    }
    return "?";
}

SaturatedOptimalCurrent::SaturatedOptimalCurrent(std::shared_ptr<const FluxMap> map, int pole_pairs)
    : map_(std::move(map)), pole_pairs_(pole_pairs), linear_(pole_pairs) {
    resolution_ = level_search::grid_resolution(*map_);
    double psi_scale = 0;
    for (const std::vector<double>* v : {&map_->table().psi_d, &map_->table().psi_q})
        for (double x : *v) psi_scale = std::max(psi_scale, std::abs(x));
    magnet_free_ = std::abs(map_->psi_m()) <= kMagnetFreeFluxRatio * psi_scale;
    const FluxPoint f0 = map_->eval(0.0, 0.0);
    nominal_L_d_ = f0.L_dd;
    nominal_L_q_ = f0.L_qq;
}

LinearMachine SaturatedOptimalCurrent::nominal_machine(double R_s, double psi_d_shift) const {
    return {map_->psi_m() + psi_d_shift, nominal_L_d_, nominal_L_q_, R_s};
}

LinearMachine SaturatedOptimalCurrent::apparent_machine(const MagnetFlux& flux, double i_d, double i_q,
                                                        double R_s) const {
    const FluxPoint f = flux.eval(i_d, i_q);
    const FluxPoint f0 = flux.eval(0.0, i_q);  // PM flux as lowered by cross-saturation
    LinearMachine m{f0.psi_d, 0.0, 0.0, R_s};
    m.L_d = std::abs(i_d) > kApparentMinCurrent_A ? (f.psi_d - f0.psi_d) / i_d : f0.L_dd;
    m.L_q = std::abs(i_q) > kApparentMinCurrent_A ? (f.psi_q - flux.eval(i_d, 0.0).psi_q) / i_q : f.L_qq;
    return m;
}

CurrentCommand SaturatedOptimalCurrent::solve(double T_ref, const OperatingLimits& lim, double R_s, double psi_d_shift,
                                              Recursion mode) {
    const MagnetFlux flux(*map_, psi_d_shift);
    CurrentCommand cmd;
    switch (mode) {
        case Recursion::nominal: cmd = linear_(nominal_machine(R_s, psi_d_shift), T_ref, lim); break;
        case Recursion::apparent: cmd = solve_recursive(T_ref, lim, R_s, flux); break;
        case Recursion::optimal:
            cmd = solve_optimal(T_ref, lim, R_s, flux);
            fault_injection::apply(cmd);
            cmd = check_optimal(cmd, T_ref, lim, R_s, flux);
            break;
    }
    memory.op_i_d = cmd.i_d;
    memory.op_i_q = cmd.i_q;
    return cmd;
}

CurrentCommand SaturatedOptimalCurrent::solve_recursive(double T_ref, const OperatingLimits& lim, double R_s,
                                                        const MagnetFlux& flux) {
    const double s = sign_of(T_ref);
    const double kT = torque_factor(pole_pairs_);
    int iterations = 0;
    // The recursion: linearise at the last point, solve with Ferrari, until it moves < 0.05 A.
    auto recurse = [&](double T, double i_d, double i_q) {
        CurrentCommand c;
        for (int k = 1; k <= recursion_max_iterations; ++k) {
            c = linear_(apparent_machine(flux, i_d, i_q, R_s), T, lim);
            ++iterations;
            const double moved = std::hypot(c.i_d - i_d, c.i_q - i_q);
            i_d = c.i_d;
            i_q = c.i_q;
            if (moved < recursion_tolerance_A) break;
        }
        return c;
    };
    // 1. T_max: the recursion on the limit point (the linearisation at the operating point
    //    says little about the limit), from the last limit point.
    const bool warm = memory.has_limit;
    const CurrentCommand top = recurse(s * 1e30, warm ? memory.limit_i_d : memory.op_i_d,
                                       s * std::abs(warm ? memory.limit_i_q : memory.op_i_q));
    memory.limit_i_d = top.i_d;
    memory.limit_i_q = top.i_q;
    memory.has_limit = true;
    const double T_max = std::max(0.0, s * kT * flux.reduced_torque(top.i_d, top.i_q));

    // 2. The command for T_ref clamped to T_max, from the last command.
    CurrentCommand cmd = top;
    if (std::abs(T_ref) < T_max) cmd = recurse(T_ref, memory.op_i_d, s * std::abs(memory.op_i_q));
    cmd.torque_max = T_max;
    cmd.feasible = top.feasible;
    cmd.iterations = iterations;
    cmd.torque = kT * flux.reduced_torque(cmd.i_d, cmd.i_q);
    return cmd;
}

namespace {

using map_newton::System;

// Newton's step tolerance, relative to I_max: converged after a step below it (5e-4 A at
// 500 A). Newton converges quadratically, so the error left is of the order of the last step
// squared over the current scale: rounding level, whether the seed was a sample or exact.
constexpr double kNewtonStepTolerance = 1e-6;
constexpr int kNewtonMaxIterations = 12;
// |v|^2 / V_max^2 at the interpolated MTPA point above which MTPA is taken to be outside the
// voltage limit without Newton (5 % in voltage).
constexpr double kClearlyOutside = 1.1025;
// Candidates for T_max on the current circle are polished while their sampled estimate is within
// this of the best polished torque (an estimate is off by the torque's curvature over a sample).
constexpr double kCandidateMargin = 0.01;  // from a Ferrari seed, 2 to 4 are usual
// A limit binds at T_max's point where it is met to this (relative, on the squares).
constexpr double kActiveLimit = 1e-7;
// A Lagrange multiplier of T_max's point below minus this (relative: the torque's gradient against
// the limit's) shows that it is not a local maximum.
constexpr double kMultiplierTolerance = 1e-6;
// Case i's seeds from one interpolated point only where the circles' MTPA points are closer than
// this fraction of the map's grid spacing.
constexpr double kOneBranchGridFraction = 0.25;

// The flux map as decision.hpp's View for one solve_optimal() call and one torque sign s. Each
// condition is Newton on the map (map_newton.hpp); where the map can have several local optima
// (the torque along a current circle), the seed is the best of the map's samples on the current
// circles (CurrentCircles), so the polished point is the global one; elsewhere the seed is
// Ferrari's point on the machine linearised at the global MTPA point. Nothing depends on earlier
// calls. Points are the map's own (i_q signed like the torque); torque() is s T', >= 0 on the side
// decided. Ferrari's seeds are for T >= 0 on the mirrored problem (omega, i_q) -> (s omega, s i_q).
struct MapView {
    struct CircleCandidate {
        CurrentPoint seed;
        double T;  // estimated s T'
        bool interior;
    };
    static constexpr int kMaxCandidates = 6;
    struct CircleCandidates {
        int n = 0;
        CircleCandidate c[kMaxCandidates];
        // Kept sorted by estimated torque, best first; when full, x replaces the weakest if better.
        void add(const CircleCandidate& x) {
            int i;
            if (n < kMaxCandidates)
                i = n++;
            else if (x.T > c[kMaxCandidates - 1].T)
                i = kMaxCandidates - 1;
            else
                return;
            for (; i > 0 && c[i - 1].T < x.T; --i) c[i] = c[i - 1];
            c[i] = x;
        }
    };

    MapView(const SaturatedOptimalCurrent& solver, const MagnetFlux& flux, const CurrentCircles& circles,
            const CircleMaxima& maxima, const OperatingLimits& lim, double R_s, double s)
        : solver(solver),
          flux(flux),
          circles(circles),
          all_maxima(maxima),
          maxima(maxima.side(s)),
          lim(lim),
          R_s(R_s),
          s(s),
          w_pos(s * lim.omega),
          V2(lim.V_max * lim.V_max * (1.0 + kLimitSlack)),
          I2(lim.I_max * lim.I_max * (1.0 + kLimitSlack)),
          exact_shift(maxima.shift == flux.shift()) {}

    // The last point's torque is kept: the decision and the command ask for T_max's again.
    double torque(CurrentPoint p) {
        if (!(p.i_d == torque_at.i_d && p.i_q == torque_at.i_q))
            torque_at = p, torque_there = s * flux.reduced_torque(p.i_d, p.i_q);
        return torque_there;
    }
    bool within_voltage(CurrentPoint p) const {
        return map_newton::voltage_sq(flux, lim.omega, R_s, p.i_d, p.i_q) <= V2;
    }
    bool within_current(CurrentPoint p) const { return p.i_d * p.i_d + p.i_q * p.i_q <= I2; }
    bool within(CurrentPoint p, double V2_max, double I2_max) const {
        return map_newton::voltage_sq(flux, lim.omega, R_s, p.i_d, p.i_q) <= V2_max &&
               p.i_d * p.i_d + p.i_q * p.i_q <= I2_max;
    }

    // The global maximum of the torque along the current circle (CircleMaxima).
    bool mtpa_at_current_limit(CurrentPoint& p) {
        constexpr int K = CurrentCircles::kRadii;
        if (!maxima.converged[K]) return false;
        if (exact_shift) {  // polished at this very shift already
            p = maxima.mtpa[K];
            return true;
        }
        return solve_from(System::mtpa_at_current, 0.0, maxima.mtpa[K], p) &&
               torque(p) >= maxima.T[K] * (1.0 - kLimitSlack);
    }
    // The most torque on the voltage limit within the current circle. Its seeds: the sampled
    // maxima of the torque along the two flux levels about V_max / |omega| (the global one).
    // Where both lie on the current circle, the torque still rises along the voltage limit at
    // I_max: the point is on the circle (false: the decision goes on to the circle) if the
    // circle's best point within the voltage limit is a local maximum of the torque within the
    // limits; if not, an MTPV point lies just inside it (Newton from there too). Where Newton
    // finds no point within the current circle and the circle's best point is not a local
    // maximum, Newton from Ferrari's MTPV point of the machine linearised where the circle's best
    // sample within the voltage limit is, and from that sample. Of the points found, the best
    // within the current limit; it is T_max only if no point of the current circle within the
    // voltage limit gives more (then it is the largest torque on the voltage limit).
    bool mtpv(CurrentPoint& p) {
        const CircleCandidates& arc = circle_within_voltage();
        const bool on_arc = arc.n > 0;
        bool found = false, found_inside = false;
        double T_p = 0.0;  // torque(p)
        auto consider = [&](const CurrentPoint& q) {
            const bool inside = within_current(q);
            const double T_q = torque(q);
            if (T_q < 0 || (found_inside && !inside)) return;
            if (!found || (inside && !found_inside) || T_q > T_p) p = q, T_p = T_q;
            found = true;
            found_inside |= inside;
        };
        CurrentPoint seeds[3], q, circle_best;
        int n_seeds = 0;
        bool on_circle = true;
        const double level = lim.V_max / std::abs(lim.omega);
        const double x =
            (level - all_maxima.psi_min) / (all_maxima.psi_max - all_maxima.psi_min) * (CircleMaxima::kFluxLevels - 1);
        if (std::isfinite(x) && x >= 0 && x <= CircleMaxima::kFluxLevels - 1) {
            const int l = std::min(static_cast<int>(x), CircleMaxima::kFluxLevels - 2);
            for (int ll : {l, l + 1}) {
                if (!maxima.has_mtpv[ll]) continue;
                seeds[n_seeds++] = maxima.mtpv[ll];
                on_circle &= maxima.mtpv_on_current_limit[ll];
            }
        }
        if (n_seeds > 0 && on_circle && current_voltage_intersection(circle_best)) {
            if (locally_maximal(circle_best)) return false;
            seeds[n_seeds++] = circle_best;
        }
        for (int i = 0; i < n_seeds; ++i)
            if (solve_from(System::mtpv, 0.0, seeds[i], q)) consider(q);
        if (!found_inside && !(current_voltage_intersection(circle_best) && locally_maximal(circle_best))) {
            const CurrentPoint at = on_arc ? arc.c[0].seed : maxima.mtpa[CurrentCircles::kRadii];
            linear::Point seed;
            if (linear::mtpv(linearised_at(at), w_pos, lim.V_max, seed) && solve(System::mtpv, 0.0, seed, q))
                consider(q);
            if (!found_inside && on_arc && solve_from(System::mtpv, 0.0, at, q)) consider(q);
        }
        if (!found) return false;
        // A local maximum on the voltage limit is T_max only if the current circle within the
        // limit gives no more: its polished points decide where its best sample's estimate comes
        // within kCandidateMargin (a sampled estimate is off by the torque's curvature over a
        // sample, which on a coarse grid exceeds the difference between the two).
        if (!found_inside || !on_arc || T_p * (1.0 - kCandidateMargin) > arc.c[0].T) return true;
        return !(current_voltage_intersection(q) && intersection_torque > T_p);
    }
    // The best point of the current circle within the voltage limit: where the circle meets the
    // voltage limit, or a local maximum of the torque along the circle between two such points.
    // Every candidate of the scan (circle_within_voltage) whose estimate comes within
    // kCandidateMargin of the best polished one is polished; the most torque wins.
    bool current_voltage_intersection(CurrentPoint& p) {
        if (intersection_done) {
            p = intersection;
            return intersection_found;
        }
        intersection_done = true;
        intersection_found = polish_arc(intersection, intersection_torque);
        p = intersection;
        return intersection_found;
    }
    // p and its torque T_p.
    bool polish_arc(CurrentPoint& p, double& T_p) {
        const CircleCandidates& arc = circle_within_voltage();
        bool found = false;
        for (int i = 0; i < arc.n; ++i) {
            if (found && arc.c[i].T < T_p * (1.0 - kCandidateMargin)) break;
            CurrentPoint q;
            double T_q;
            if (polish(arc.c[i], q, T_q) && (!found || T_q > T_p)) p = q, T_p = T_q, found = true;
        }
        return found;
    }
    bool polish(const CircleCandidate& c, CurrentPoint& p, double& T_p) {
        if (c.interior)
            return solve_from(System::mtpa_at_current, 0.0, c.seed, p) && within_voltage(p) && (T_p = torque(p)) >= 0;
        if (!(solve_from(System::current_voltage, 0.0, c.seed, p) && (T_p = torque(p)) >= 0)) return false;
        // A maximum of the torque along the circle within a sample's width of the voltage limit.
        CurrentPoint q;
        if (!map_newton::voltage_limit_binds_on_circle(flux, lim.omega, R_s, s, p.i_d, p.i_q) &&
            solve_from(System::mtpa_at_current, 0.0, p, q) && within_voltage(q)) {
            const double T_q = torque(q);
            if (T_q > T_p) p = q, T_p = T_q;
        }
        return true;
    }
    // Case i: the global minimum current for T', bracketed between two current circles whose MTPA
    // torques straddle T'. Newton from the MTPA points interpolated between the two circles; where
    // they lie on different maxima of the torque along the circles (the global one jumps between
    // two local ones), from each, and the least current wins.
    bool mtpa(double T_red, CurrentPoint& p) {
        constexpr int K = CurrentCircles::kRadii;
        int k = 1;
        while (k < K && maxima.T[k] < T_red) ++k;
        const double T0 = maxima.T[k - 1], T1 = maxima.T[k];
        const double t = T1 > T0 ? std::clamp((T_red - T0) / (T1 - T0), 0.0, 1.0) : 1.0;
        const CurrentPoint a = maxima.mtpa[k - 1], b = maxima.mtpa[k];
        const double r = circles.radius(k - 1) + t * (circles.radius(k) - circles.radius(k - 1));
        // One maximum: the two points are less than two samples apart in angle (the origin is on
        // every one), and at radius r less than a fraction of the map's grid spacing apart: a
        // spline bends on the grid's scale, and on a coarse grid (the Prius map's 10/20 A) the
        // least current's angle can hop between shallow minima of |i| along the torque curve
        // within a cell; then Newton starts from both circles' points and the least current wins.
        const double sample_angle = 2.0 * kPi / CurrentCircles::kAngles;
        const double angle = std::atan2(std::abs(a.i_d * b.i_q - a.i_q * b.i_d), a.i_d * b.i_d + a.i_q * b.i_q);
        const bool one_branch =
            k == 1 || (angle < 2.0 * sample_angle && r * angle < kOneBranchGridFraction * solver.resolution());
        auto scaled = [&](CurrentPoint x, double radius) {
            return CurrentPoint{x.i_d * r / radius, x.i_q * r / radius};
        };
        CurrentPoint seeds[2] = {{a.i_d + t * (b.i_d - a.i_d), a.i_q + t * (b.i_q - a.i_q)}, {}};
        int n_seeds = 1;
        if (!one_branch) {
            seeds[0] = scaled(b, circles.radius(k));
            seeds[n_seeds++] = scaled(a, circles.radius(k - 1));
        }
        // On one maximum the interpolated point is within a fraction of a per cent of MTPA, on two
        // each seed is its circle's MTPA point at this current: a voltage that far above the limit
        // at every seed means Case ii, without Newton (were it wrong, the check's least-current
        // test would catch the Case ii point).
        bool clearly_outside = true;
        for (int i = 0; i < n_seeds; ++i) clearly_outside &= !within(seeds[i], kClearlyOutside * V2, INFINITY);
        if (clearly_outside) return false;
        bool found = false;
        for (int i = 0; i < n_seeds; ++i) {
            CurrentPoint q;
            if (!(solve_from(System::mtpa, s * T_red, seeds[i], q) && within_current(q))) continue;
            if (!found || q.i_d * q.i_d + q.i_q * q.i_q < p.i_d * p.i_d + p.i_q * p.i_q) p = q;
            found = true;
        }
        if (found) mtpa_point = p, have_mtpa_point = true;
        return found;
    }
    // Case ii: Newton from Ferrari's point on the machine linearised at the MTPA point for T', and
    // from Ferrari's point and the point itself of T_max (close to Case ii's just below T_max);
    // the least current within the current limit wins.
    bool voltage_limit(double T_red, CurrentPoint& p) {
        bool found = false;
        auto consider = [&](const CurrentPoint& q) {
            if (!within_current(q) || (found && q.i_d * q.i_d + q.i_q * q.i_q >= p.i_d * p.i_d + p.i_q * p.i_q)) return;
            p = q;
            found = true;
        };
        linear::Point seed;
        CurrentPoint q;
        const CurrentPoint linearised[2] = {have_mtpa_point ? mtpa_point : top_point, top_point};
        for (int i = 0; i < (have_mtpa_point ? 2 : 1); ++i) {
            if (linear::voltage_limit(linearised_at(linearised[i]), w_pos, lim.V_max, T_red, seed) &&
                solve(System::voltage_limit, T_red, seed, q))
                consider(q);
            if (found) return true;
        }
        if (solve_from(System::voltage_limit, s * T_red, top_point, q)) consider(q);
        return found;
    }
    // T_max's check, cheap (one map evaluation): the decision's point is a local maximum of the
    // torque within the limits (map_newton::torque_local_maximum). A corner of the two limits with
    // a negative multiplier of the current limit has more torque inward along the voltage limit
    // (an MTPV point inside the current circle the decision's seeds missed).
    bool locally_maximal(const decision::Choice& top) {
        const CurrentPoint p = top.point;
        // MTPA at I_max: the circle's polished global maximum, if on the circle.
        if (top.region == Region::mtpa)
            return p.i_d * p.i_d + p.i_q * p.i_q >= lim.I_max * lim.I_max * (1.0 - kActiveLimit);
        return locally_maximal(p);
    }
    // Remembers the last point shown a local maximum (mtpv() tests the circle's best point, which
    // then becomes T_max's).
    bool locally_maximal(CurrentPoint p) {
        if (p.i_d == maximal_at.i_d && p.i_q == maximal_at.i_q) return true;
        if (!map_newton::torque_local_maximum(flux, lim.omega, R_s, s, p.i_d, p.i_q, lim.I_max, lim.V_max, kActiveLimit,
                                              kMultiplierTolerance))
            return false;
        maximal_at = p;
        return true;
    }

    bool zero_torque(CurrentPoint& p) {
        p = {0.0, 0.0};
        if (within_voltage(p)) return true;
        linear::Point seed;
        return linear::zero_torque(linearised_at({0.0, 0.0}), w_pos, lim.V_max, seed) &&
               solve(System::voltage_limit, 0.0, seed, p);
    }

    using CircleSample = CurrentCircles::Sample;
    // Where the torque along the current circle |i| = I_max may be largest within the voltage
    // limit, from its samples: each local maximum between two samples within the limit, and each
    // crossing of the limit (the point where |v|^2 - V^2 interpolates to zero between a sample
    // within and one outside, its torque interpolated too). The kMaxCandidates best, best first.
    const CircleCandidates& circle_within_voltage() {
        if (arc_scanned) return arc;
        arc_scanned = true;
        constexpr int K = CurrentCircles::kRadii, N = CurrentCircles::kAngles;
        const CircleSample* x = &circles.at(K, 0);  // the circle's N samples, in order of angle
        double T[N], g[N];
        for (int j = 0; j < N; ++j) {
            T[j] = s * x[j].torque(flux.shift());
            g[j] = voltage_sq(x[j]) - V2;
        }
        const bool left_half = solver.magnet_free();
        for (int j = 0; j < N; ++j) {
            if (!(g[j] <= 0) || (left_half && x[j].i_d > 0)) continue;
            const int prev = j > 0 ? j - 1 : N - 1, next = j < N - 1 ? j + 1 : 0;
            if (g[prev] <= 0 && g[next] <= 0 && T[j] >= T[prev] && T[j] >= T[next])
                arc.add({{x[j].i_d, x[j].i_q}, T[j], true});
            for (int o : {prev, next}) {
                if (g[o] <= 0) continue;
                const double t = g[j] / (g[j] - g[o]);
                arc.add({{x[j].i_d + t * (x[o].i_d - x[j].i_d), x[j].i_q + t * (x[o].i_q - x[j].i_q)},
                         T[j] + t * (T[o] - T[j]),
                         false});
            }
        }
        return arc;
    }
    // |v|^2 at a sample, from its stored flux.
    double voltage_sq(const CircleSample& x) const {
        const double v_d = R_s * x.i_d - lim.omega * x.psi_q, v_q = R_s * x.i_q + lim.omega * (x.psi_d + flux.shift());
        return v_d * v_d + v_q * v_q;
    }
    // The machine linearised at a point of the map, mirrored to T >= 0.
    LinearMachine linearised_at(CurrentPoint p) const { return solver.apparent_machine(flux, p.i_d, s * p.i_q, R_s); }
    // Newton on `sys` from Ferrari's mirrored seed.
    bool solve(System sys, double T_red, linear::Point seed, CurrentPoint& p) {
        return solve_from(sys, s * T_red, {seed.i_d, s * seed.i_q}, p);
    }
    // Newton on `sys` from a point of the map; T_target signed like the torque.
    bool solve_from(System sys, double T_target, CurrentPoint seed, CurrentPoint& p) {
        const map_newton::Problem P{sys, lim.omega, R_s, T_target, lim.V_max, lim.I_max};
        const auto r =
            map_newton::solve(flux, P, seed.i_d, seed.i_q, kNewtonMaxIterations, kNewtonStepTolerance * lim.I_max);
        iterations += r.iterations;
        p = {r.i_d, r.i_q};
        return r.converged;
    }

    const SaturatedOptimalCurrent& solver;
    const MagnetFlux& flux;
    const CurrentCircles& circles;
    const CircleMaxima& all_maxima;
    const CircleMaxima::Side& maxima;
    const OperatingLimits& lim;
    const double R_s, s, w_pos;
    const double V2, I2;     // squared limits with slack, for points computed on a limit
    const bool exact_shift;  // the circles' maxima were found at this magnet shift
    int iterations = 0;
    bool arc_scanned = false;
    CircleCandidates arc;
    bool intersection_done = false, intersection_found = false;
    CurrentPoint intersection{0.0, 0.0};
    double intersection_torque = 0.0;
    CurrentPoint mtpa_point{0.0, 0.0};
    bool have_mtpa_point = false;
    CurrentPoint top_point{0.0, 0.0};  // T_max's, once decided
    CurrentPoint torque_at{NAN, NAN}, maximal_at{NAN, NAN};
    double torque_there = 0.0;
};

}  // namespace

const CircleMaxima& SaturatedOptimalCurrent::circle_maxima(const MagnetFlux& flux, double I_max) {
    if (!circles_ || !(circles_->I_max() == I_max)) {
        circles_ = std::make_shared<const CurrentCircles>(*map_, I_max);
        maxima_.shift = NAN;
    }
    const double shift = CircleMaxima::kShiftStep * std::round(flux.shift() / CircleMaxima::kShiftStep);
    if (maxima_.shift == shift) return maxima_;
    maxima_.shift = shift;
    const MagnetFlux rounded(flux.map(), shift);
    for (int side = 0; side < 2; ++side) {
        const double s = side == 0 ? 1.0 : -1.0;
        CircleMaxima::Side& m = maxima_.sides[side];
        m.T[0] = 0.0;
        m.mtpa[0] = {0.0, 0.0};
        m.converged[0] = true;
        for (int k = 1; k <= CurrentCircles::kRadii; ++k) {
            // Newton stays on the best sample's maximum: the samples are 2.8 degrees apart, each
            // maximum's basin far wider.
            const CurrentCircles::Sample& x = circles_->at(k, circles_->best_angle(k, s, shift, magnet_free_));
            const map_newton::Problem P{System::mtpa_at_current, 0.0, 0.0, 0.0, 0.0, circles_->radius(k)};
            const auto r =
                map_newton::solve(rounded, P, x.i_d, x.i_q, kNewtonMaxIterations, kNewtonStepTolerance * I_max);
            const double T = s * rounded.reduced_torque(r.i_d, r.i_q), T_sample = s * x.torque(shift);
            m.converged[k] = r.converged && T >= T_sample;
            m.mtpa[k] = m.converged[k] ? CurrentPoint{r.i_d, r.i_q} : CurrentPoint{x.i_d, x.i_q};
            m.T[k] = m.converged[k] ? T : T_sample;
        }
    }
    // The flux levels' MTPV seeds: every crossing of a level between neighbouring samples of a circle.
    constexpr int K = CurrentCircles::kRadii, N = CurrentCircles::kAngles, L = CircleMaxima::kFluxLevels;
    auto psi_of = [&](const CurrentCircles::Sample& x) { return std::hypot(x.psi_d + shift, x.psi_q); };
    maxima_.psi_min = INFINITY, maxima_.psi_max = 0.0;
    for (int k = 1; k <= K; ++k)
        for (int j = 0; j < N; ++j) {
            const double psi = psi_of(circles_->at(k, j));
            maxima_.psi_min = std::min(maxima_.psi_min, psi), maxima_.psi_max = std::max(maxima_.psi_max, psi);
        }
    double best[2][L];
    for (int side = 0; side < 2; ++side)
        for (int l = 0; l < L; ++l)
            best[side][l] = -INFINITY, maxima_.sides[side].has_mtpv[l] = false,
            maxima_.sides[side].mtpv_on_current_limit[l] = false;
    for (int k = 1; k <= K; ++k)
        for (int j = 0; j < N; ++j) {
            const CurrentCircles::Sample &x = circles_->at(k, j), &y = circles_->at(k, j + 1);
            if (magnet_free_ && (x.i_d > 0 || y.i_d > 0)) continue;
            const double a = psi_of(x), b = psi_of(y);
            const double lo = std::min(a, b), hi = std::max(a, b);
            const double step = (maxima_.psi_max - maxima_.psi_min) / (L - 1);
            for (int l = std::max(0, static_cast<int>(std::ceil((lo - maxima_.psi_min) / step))); l < L; ++l) {
                const double level = maxima_.psi_level(l);
                if (level > hi) break;
                const double t = b != a ? (level - a) / (b - a) : 0.0;
                const CurrentPoint p{x.i_d + t * (y.i_d - x.i_d), x.i_q + t * (y.i_q - x.i_q)};
                const double T = x.torque(shift) + t * (y.torque(shift) - x.torque(shift));
                for (int side = 0; side < 2; ++side) {
                    const double sT = side == 0 ? T : -T;
                    CircleMaxima::Side& m = maxima_.sides[side];
                    if (sT > best[side][l])
                        best[side][l] = sT, m.mtpv[l] = p, m.has_mtpv[l] = true, m.mtpv_on_current_limit[l] = k == K;
                }
            }
        }
    return maxima_;
}

CurrentCommand SaturatedOptimalCurrent::solve_optimal(double T_ref, const OperatingLimits& lim, double R_s,
                                                      const MagnetFlux& flux) {
    const double s = sign_of(T_ref);
    const double kT = torque_factor(pole_pairs_);
    const CircleMaxima& maxima = circle_maxima(flux, lim.I_max);  // makes circles_ on the first call
    MapView view(*this, flux, *circles_, maxima, lim, R_s, s);
    top_check_ = CheckRecord{};

    // 1. The largest torque reachable now (this torque sign), on the map.
    decision::Choice top = decision::max_torque(view);
    fault_injection::apply_top(top.point);
    if (!top.feasible) {
        // No limit point on the map: above the maximum speed, or Newton failed. Fall back to the
        // paper's recursion for this step.
        CurrentCommand fb = solve_recursive(T_ref, lim, R_s, flux);
        fb.iterations += view.iterations;
        fb.converged = false;
        return fb;
    }

    // 2. The command: clamped to T_max, else MTPA, else the voltage limit (Case ii).
    const double T_red = std::abs(T_ref) / kT;
    auto command_below = [&](const decision::Choice& t) {
        const double T_top = std::max(0.0, view.torque(t.point));  // reduced, >= 0
        view.top_point = t.point;
        const decision::Choice c = decision::command(view, T_red, t);
        CurrentCommand cmd;
        cmd.i_d = c.point.i_d;
        cmd.i_q = c.point.i_q;
        cmd.region = c.region;  // its torque: the check's evaluation on the map (check_command)
        cmd.torque_max = kT * T_top;
        // Below T_max the command is T_max's point only at the edge of reach (neither case had a point).
        cmd.converged = T_red >= T_top || c.point.i_d != t.point.i_d || c.point.i_q != t.point.i_q;
        return cmd;
    };
    CurrentCommand cmd = command_below(top);

    // 3. T_max's check: where its point is not shown to be a local maximum within the limits, the
    //    robust search's (max_torque_search.hpp) decides; more torque there fails the check.
    if (!view.locally_maximal(top)) {
        const max_torque_search::Result r =
            max_torque_search::max_torque(flux, *circles_, s, lim, R_s, resolution_, magnet_free_);
        view.iterations += r.evaluations;
        top_check_.searched_max = true;
        const double T_top = cmd.torque_max / kT;
        if (r.found && r.torque > T_top + kTorqueTolerance * std::max(T_top, r.torque)) {
            CurrentCommand rejected = cmd;
            rejected.torque = kT * flux.reduced_torque(rejected.i_d, rejected.i_q);
            cmd = command_below({r.point, limit_region(flux, lim, R_s, r.point), true});
            top_check_.finding = CheckFinding::torque_max;
            top_check_.rejected = rejected;
            top_check_.T_target = s * std::min(std::abs(T_ref), cmd.torque_max);
            top_check_.T_made = rejected.torque;
            top_check_.replaced = true;
        }
    }
    cmd.iterations = view.iterations;
    return cmd;
}

namespace {

// The mirror of a command through the origin, where the map is symmetric there (a magnet-free
// machine: psi(-i) = -psi(i), so torque and |v| are the same at -i): the tie convention takes the
// one with i_d <= 0. Symmetric means the mirror's torque and voltage agree to kTieTolerance.
bool mirror_ties(const MagnetFlux& flux, double omega, double R_s, CurrentPoint p, double T_scale, double V2) {
    if (!(p.i_d > 0.0)) return false;
    const double T = flux.reduced_torque(p.i_d, p.i_q), T_m = flux.reduced_torque(-p.i_d, -p.i_q);
    if (!(std::abs(T - T_m) <= level_search::kTieTolerance * T_scale)) return false;
    const double g = map_newton::voltage_sq(flux, omega, R_s, p.i_d, p.i_q);
    const double g_m = map_newton::voltage_sq(flux, omega, R_s, -p.i_d, -p.i_q);
    return g_m <= V2 || std::abs(g - g_m) <= level_search::kTieTolerance * V2;
}

}  // namespace

// Which limits bind at a point of T_max (the robust search's): the region it belongs to.
Region SaturatedOptimalCurrent::limit_region(const MagnetFlux& flux, const OperatingLimits& lim, double R_s,
                                             CurrentPoint p) {
    const bool on_voltage =
        map_newton::voltage_sq(flux, lim.omega, R_s, p.i_d, p.i_q) >= lim.V_max * lim.V_max * (1.0 - kActiveLimit);
    const bool on_current = p.i_d * p.i_d + p.i_q * p.i_q >= lim.I_max * lim.I_max * (1.0 - kActiveLimit);
    if (on_voltage && on_current) return Region::current_and_voltage_limit;
    return on_voltage ? Region::mtpv : Region::mtpa;
}

CurrentCommand SaturatedOptimalCurrent::check_optimal(CurrentCommand cmd, double T_ref, const OperatingLimits& lim,
                                                      double R_s, const MagnetFlux& flux) {
    cmd = check_command(cmd, T_ref, lim, R_s, flux);
    // T_max's finding (solve_optimal) first: the command was made from its replacement.
    if (top_check_.finding != CheckFinding::passed) last_check = top_check_;
    last_check.searched_max = top_check_.searched_max;
    return cmd;
}

CurrentCommand SaturatedOptimalCurrent::check_command(CurrentCommand cmd, double T_ref, const OperatingLimits& lim,
                                                      double R_s, const MagnetFlux& flux) {
    last_check = CheckRecord{};
    const double s = sign_of(T_ref);
    const double kT = torque_factor(pole_pairs_);
    const double T_top = cmd.torque_max / kT;  // reduced, >= 0
    const double T_red = std::min(std::abs(T_ref) / kT, T_top);
    const bool clamped = std::abs(T_ref) / kT >= T_top;
    const double V2 = lim.V_max * lim.V_max * (1.0 + kLimitTolerance);
    const double I2 = lim.I_max * lim.I_max * (1.0 + kLimitTolerance);
    const double scale = std::max(T_top, 1e-12);
    auto fail = [&](CheckFinding f, double T_made) {
        if (last_check.finding != CheckFinding::passed) return;
        last_check.finding = f;
        last_check.rejected = cmd;
        last_check.T_target = s * kT * T_red;
        last_check.T_made = kT * T_made;
    };
    if (!cmd.feasible) return cmd;  // above the maximum speed: the controller warns of it
    const CurrentPoint p{cmd.i_d, cmd.i_q};
    // The tie convention: of two mirror optima, the one with i_d <= 0.
    if (magnet_free_ && mirror_ties(flux, lim.omega, R_s, p, scale, V2)) cmd.i_d = -cmd.i_d, cmd.i_q = -cmd.i_q;
    if (magnet_free_ && cmd.i_d > kBranchTolerance * lim.I_max) fail(CheckFinding::branch, NAN);
    if (!(std::isfinite(cmd.i_d) && std::isfinite(cmd.i_q))) {
        cmd.torque = NAN;
        fail(CheckFinding::not_finite, NAN);
    } else {
        const FluxPoint f = flux.eval(cmd.i_d, cmd.i_q);
        const double T = f.psi_d * cmd.i_q - f.psi_q * cmd.i_d;
        cmd.torque = kT * T;  // what the command makes, reported as its torque
        const double vd = R_s * cmd.i_d - lim.omega * f.psi_q, vq = R_s * cmd.i_q + lim.omega * f.psi_d;
        const double c = cmd.i_d * cmd.i_d + cmd.i_q * cmd.i_q;
        if (last_check.finding == CheckFinding::branch) last_check.T_made = last_check.rejected.torque = kT * T;
        if (c > I2) fail(CheckFinding::current_limit, T);
        if (vd * vd + vq * vq > V2) fail(CheckFinding::voltage_limit, T);
        if (std::abs(s * T - T_red) > kTorqueTolerance * scale) fail(CheckFinding::torque, T);
        if (!clamped && T_red > 0 && last_check.finding == CheckFinding::passed) {
            // Least current, globally: no current circle inside the command's holds a point
            // (its polished MTPA) that makes the torque within the voltage limit.
            const CircleMaxima& maxima = circle_maxima(flux, lim.I_max);
            const CircleMaxima::Side& side = maxima.side(s);
            const double r = std::sqrt(c) * (1.0 - kCurrentTolerance) - kSmallCurrent * lim.I_max;
            const int k = std::min(CurrentCircles::kRadii, static_cast<int>(std::floor(r / circles_->radius(1))));
            if (k >= 1 && side.converged[k] && side.T[k] >= T_red &&
                map_newton::voltage_sq(flux, lim.omega, R_s, side.mtpa[k].i_d, side.mtpa[k].i_q) <= V2)
                fail(CheckFinding::not_least_current, T);
            // And locally: on the voltage limit, the voltage must bind (its KKT multiplier >= 0:
            // along the torque curve, less current means more voltage).
            if (cmd.region == Region::voltage_limit) {
                const double Td = f.L_dd * cmd.i_q - f.L_qd * cmd.i_d - f.psi_q;
                const double Tq = f.L_dq * cmd.i_q + f.psi_d - f.L_qq * cmd.i_d;
                const double gd = 2.0 * (vd * (R_s - lim.omega * f.L_qd) + vq * lim.omega * f.L_dd);
                const double gq = 2.0 * (vd * -lim.omega * f.L_qq + vq * (R_s + lim.omega * f.L_dq));
                // grad c = lambda grad T - mu grad g; crossed with grad T: mu = -(c x T) / (g x T).
                const double cxT = 2.0 * (cmd.i_d * Tq - cmd.i_q * Td), gxT = gd * Tq - gq * Td;
                const double mu = -cxT / gxT;
                const double scale_mu = std::sqrt(c) / std::max(std::sqrt(gd * gd + gq * gq), 1e-300);
                if (mu < -1e-6 * scale_mu) fail(CheckFinding::not_least_current, T);
            }
        }
    }
    if (last_check.finding == CheckFinding::passed || T_red <= 0 || clamped) return cmd;
    // The robust search takes over.
    const level_search::Result r =
        level_search::least_current(flux, *circles_, s, T_red, lim, R_s, resolution_, magnet_free_);
    if (!r.found) return cmd;
    CurrentCommand out = cmd;
    out.i_d = r.point.i_d;
    out.i_q = r.point.i_q;
    out.region = r.region;
    out.torque = kT * flux.reduced_torque(out.i_d, out.i_q);
    out.iterations += r.evaluations;
    out.converged = true;
    last_check.replaced = true;
    return out;
}

CurrentCommand SaturatedOptimalCurrent::checked(const CurrentCommand& cmd, double T_ref, const OperatingLimits& lim,
                                                double R_s, double psi_d_shift) {
    const MagnetFlux flux(*map_, psi_d_shift);
    CurrentCommand exact = check_optimal(solve_optimal(T_ref, lim, R_s, flux), T_ref, lim, R_s, flux);
    const CheckRecord exact_check = last_check;
    last_check = CheckRecord{};
    const double s = sign_of(T_ref), kT = torque_factor(pole_pairs_);
    const double T_cmd = s * std::min(std::abs(T_ref), exact.torque_max);
    const double scale = std::max(exact.torque_max, 1e-12);
    auto fail = [&](CheckFinding f, double T_made) {
        if (last_check.finding != CheckFinding::passed) return;
        last_check.finding = f;
        last_check.rejected = cmd;
        last_check.T_target = T_cmd;
        last_check.T_made = T_made;
    };
    if (!(std::isfinite(cmd.i_d) && std::isfinite(cmd.i_q))) {
        fail(CheckFinding::not_finite, NAN);
    } else if (exact.feasible) {
        const double T = kT * flux.reduced_torque(cmd.i_d, cmd.i_q);
        const double I = std::hypot(cmd.i_d, cmd.i_q), I_exact = std::hypot(exact.i_d, exact.i_q);
        if (I > lim.I_max * (1.0 + kLimitTolerance)) fail(CheckFinding::current_limit, T);
        if (map_newton::voltage_sq(flux, lim.omega, R_s, cmd.i_d, cmd.i_q) >
            lim.V_max * lim.V_max * (1.0 + kLimitTolerance))
            fail(CheckFinding::voltage_limit, T);
        if (std::abs(T - T_cmd) > kTorqueTolerance * scale) fail(CheckFinding::torque, T);
        if (std::abs(cmd.torque_max - exact.torque_max) > kTorqueTolerance * scale) fail(CheckFinding::torque_max, T);
        if (std::abs(T_ref) < exact.torque_max && I > I_exact * (1.0 + kCurrentTolerance) + kSmallCurrent * lim.I_max)
            fail(CheckFinding::not_least_current, T);
    }
    if (last_check.finding == CheckFinding::passed) {
        if (exact_check.finding != CheckFinding::passed) last_check = exact_check;
        return cmd;
    }
    exact.iterations += cmd.iterations;
    last_check.replaced = true;
    return exact;
}

}  // namespace ipmsm
