#include "control/saturated_optimal_current.hpp"

#include <algorithm>
#include <cmath>

#include "control/map_newton.hpp"

namespace ipmsm {
namespace {

// Below this current an apparent inductance (flux / current) is ill-defined: use the incremental one.
constexpr double kApparentMinCurrent_A = 1e-3;
// Relative slack on the limits for points computed on a limit.
constexpr double kLimitSlack = 1e-9;

double sign_of(double T) { return T < 0 ? -1.0 : 1.0; }

}  // namespace

SaturatedOptimalCurrent::SaturatedOptimalCurrent(std::shared_ptr<const FluxMap> map, int pole_pairs)
    : map_(std::move(map)), pole_pairs_(pole_pairs), linear_(pole_pairs) {
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

CurrentCommand SaturatedOptimalCurrent::solve(double T_ref, const OperatingLimits& lim, double R_s,
                                              double psi_d_shift, Recursion mode) {
    const MagnetFlux flux(*map_, psi_d_shift);
    CurrentCommand cmd;
    switch (mode) {
        case Recursion::nominal:
            cmd = linear_(nominal_machine(R_s, psi_d_shift), T_ref, lim);
            break;
        case Recursion::apparent: cmd = solve_recursive(T_ref, lim, R_s, flux); break;
        case Recursion::optimal: cmd = solve_optimal(T_ref, lim, R_s, flux); break;
    }
    memory.op_i_d = cmd.i_d;
    memory.op_i_q = cmd.i_q;
    return cmd;
}

CurrentCommand SaturatedOptimalCurrent::solve_recursive(double T_ref, const OperatingLimits& lim,
                                                        double R_s, const MagnetFlux& flux) {
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

// Newton's step tolerance, relative to I_max: converged after a step below it (0.025 A at
// 500 A). Newton converges quadratically, so the error left is of the order of the last step
// squared over the current scale: below 1e-7 I_max on the default and the measured map.
constexpr double kNewtonStepTolerance = 5e-5;
constexpr int kNewtonMaxIterations = 12;  // from a Ferrari seed, 2 to 4 are usual

// The map-Newton solves of one solve_optimal() call for one torque sign s. The Ferrari seeds
// (linear::) are computed for T >= 0 on the mirrored problem (omega, i_q) -> (s omega, s i_q).
struct MapNewton {
    MapNewton(const MagnetFlux& flux, const OperatingLimits& lim, double R_s, double s)
        : flux(flux), lim(lim), R_s(R_s), s(s), w_pos(s * lim.omega),
          V2(lim.V_max * lim.V_max * (1.0 + kLimitSlack)), I2(lim.I_max * lim.I_max * (1.0 + kLimitSlack)) {}

    map_newton::Result solve(System sys, double T_red, linear::Point seed) {
        const map_newton::Problem P{sys, lim.omega, R_s, T_red, lim.V_max, lim.I_max};
        const auto r = map_newton::solve(flux, P, seed.i_d, seed.i_q, kNewtonMaxIterations,
                                         kNewtonStepTolerance * lim.I_max);
        iterations += r.iterations;
        return r;
    }
    linear::Point mirrored(linear::Point p) const { return {p.i_d, s * p.i_q}; }
    // Limit tests at a point p (anything with i_d, i_q): a Newton result or a seed.
    template <class P>
    bool within_voltage(const P& p) const {
        return map_newton::voltage_sq(flux, lim.omega, R_s, p.i_d, p.i_q) <= V2;
    }
    template <class P>
    bool within_current(const P& p) const {
        return p.i_d * p.i_d + p.i_q * p.i_q <= I2;
    }
    bool both_limits_active(const map_newton::Result& r) const {
        return map_newton::current_voltage_is_optimal(flux, lim.omega, R_s, s, r.i_d, r.i_q);
    }

    const MagnetFlux& flux;
    const OperatingLimits& lim;
    const double R_s, s, w_pos;
    const double V2, I2;  // squared limits with slack, for points computed on a limit
    int iterations = 0;
};

// A T_max point on the map.
struct MapLimit {
    linear::Point point;
    Region region;
};

// The T_max region and point predicted from Ferrari on the linearised machine, in the order of
// linear::max_torque(), except that MTPA at the current limit is judged by the voltage on the
// map at Ferrari's point: the machine is linearised at the last limit point, often far from
// I_max, and its voltage there is the least reliable part of the prediction. The seed is for
// T >= 0 (mirrored).
bool predicted_region(const MapNewton& m, const LinearMachine& lin, linear::Point& seed, Region& region) {
    seed = linear::mtpa_at_current(lin, m.lim.I_max);
    region = Region::mtpa;
    if (m.within_voltage(m.mirrored(seed))) return true;
    region = Region::mtpv;
    if (linear::mtpv(lin, m.w_pos, m.lim.V_max, seed) && m.within_current(seed) &&
        linear::reduced_torque(lin, seed.i_d, seed.i_q) >= 0)
        return true;
    region = Region::current_and_voltage_limit;
    return linear::current_voltage_intersection(lin, m.w_pos, m.lim.V_max, m.lim.I_max, seed) &&
           linear::reduced_torque(lin, seed.i_d, seed.i_q) >= 0;
}

// T_max on the map in a given region: Newton on that region's system from a Ferrari seed (for
// T >= 0), then the limit the region leaves free must hold at the result; on the intersection
// of both limits, if `check_kkt`, also the signs of the multipliers.
bool limit_on_map(MapNewton& m, Region region, linear::Point seed, bool check_kkt, MapLimit& out) {
    map_newton::Result r{};
    bool ok = false;
    switch (region) {
        case Region::mtpa:
            r = m.solve(System::mtpa_at_current, 0, m.mirrored(seed));
            ok = r.converged && m.within_voltage(r);
            break;
        case Region::mtpv:
            r = m.solve(System::mtpv, 0, m.mirrored(seed));
            ok = r.converged && m.within_current(r);
            break;
        case Region::current_and_voltage_limit:
            r = m.solve(System::current_voltage, 0, m.mirrored(seed));
            ok = r.converged && (!check_kkt || m.both_limits_active(r));
            break;
        default: break;
    }
    if (ok) out = {{r.i_d, r.i_q}, region};
    return ok;
}

// T_max with one Newton solve: on the predicted region, from Ferrari's point, confirmed on the
// map by the condition that makes that region the optimum. False if the confirmation fails
// (the prediction was wrong, or Newton did not converge).
bool predicted_limit(MapNewton& m, const LinearMachine& lin, MapLimit& out) {
    linear::Point seed;
    Region region;
    return predicted_region(m, lin, seed, region) && limit_on_map(m, region, seed, true, out);
}

// T_max by elimination: MTPA at the current limit unless its voltage is too high, then MTPV
// unless its current is too high, then the intersection of the two limits.
bool limit_by_elimination(MapNewton& m, const LinearMachine& lin, MapLimit& out) {
    if (limit_on_map(m, Region::mtpa, linear::mtpa_at_current(lin, m.lim.I_max), false, out)) return true;
    linear::Point seed;
    if (linear::mtpv(lin, m.w_pos, m.lim.V_max, seed) && limit_on_map(m, Region::mtpv, seed, false, out))
        return true;
    return linear::current_voltage_intersection(lin, m.w_pos, m.lim.V_max, m.lim.I_max, seed) &&
           limit_on_map(m, Region::current_and_voltage_limit, seed, false, out);
}

}  // namespace

CurrentCommand SaturatedOptimalCurrent::solve_optimal(double T_ref, const OperatingLimits& lim,
                                                      double R_s, const MagnetFlux& flux) {
    const double s = sign_of(T_ref);
    const double kT = torque_factor(pole_pairs_);
    MapNewton m(flux, lim, R_s, s);

    // Ferrari seeds from the machine linearised (apparent inductances) at the last solutions.
    auto linearised_at = [&](double i_d, double i_q) { return apparent_machine(flux, i_d, s * std::abs(i_q), R_s); };
    const LinearMachine lin_lim = memory.has_limit ? linearised_at(memory.limit_i_d, memory.limit_i_q)
                                                   : linearised_at(memory.op_i_d, memory.op_i_q);

    // 1. The largest torque reachable now (this torque sign), on the map.
    MapLimit top;
    if (!predicted_limit(m, lin_lim, top) && !limit_by_elimination(m, lin_lim, top)) {
        // No exact limit point on the map: above the maximum speed, or Newton failed.
        // Fall back to the paper's recursion for this step.
        CurrentCommand fb = solve_recursive(T_ref, lim, R_s, flux);
        fb.iterations += m.iterations;
        fb.converged = false;
        return fb;
    }
    const double T_red_top = flux.reduced_torque(top.point.i_d, top.point.i_q);
    const double T_top = std::max(0.0, s * T_red_top);  // reduced, >= 0
    memory.limit_i_d = top.point.i_d;
    memory.limit_i_q = top.point.i_q;
    memory.has_limit = true;

    // 2. The command: clamped to T_max, else MTPA, else the voltage ellipse (Case ii).
    const double T_red = std::abs(T_ref) / kT;
    linear::Point p = top.point;
    Region region = top.region;
    bool converged = true;
    if (T_red < T_top) {
        const double target = s * T_red;
        const LinearMachine lin_op = linearised_at(memory.op_i_d, memory.op_i_q);
        // Below the base speed for this torque side (T_max is MTPA) try MTPA first. In field
        // weakening, the Ferrari Case ii point and its a-priori test say which to try first;
        // the same test on the map confirms it (or sends us to the other).
        linear::Point case_ii{};
        const bool have_case_ii = top.region != Region::mtpa && T_red > 0 &&
                                  linear::voltage_limit(lin_op, m.w_pos, lim.V_max, T_red, case_ii);
        auto try_mtpa = [&]() {
            const auto r = m.solve(System::mtpa, target, m.mirrored(linear::mtpa(lin_op, T_red)));
            if (!r.converged || !m.within_voltage(r) || !m.within_current(r)) return false;
            p = {r.i_d, r.i_q};
            region = Region::mtpa;
            return true;
        };
        auto try_voltage_limit = [&](bool must_be_optimal) {
            linear::Point seed = case_ii;
            if (!have_case_ii) {
                const bool have = T_red > 0 ? linear::voltage_limit(lin_op, m.w_pos, lim.V_max, T_red, seed)
                                            : linear::zero_torque(lin_op, m.w_pos, lim.V_max, seed);
                if (!have) seed = m.mirrored(top.point);
            }
            const auto r = m.solve(System::voltage_limit, target, m.mirrored(seed));
            if (!r.converged || !m.within_current(r)) return false;
            if (must_be_optimal && !map_newton::voltage_limit_is_optimal(flux, lim.omega, R_s, r.i_d, r.i_q)) return false;
            p = {r.i_d, r.i_q};
            region = Region::voltage_limit;
            return true;
        };
        const bool voltage_first = have_case_ii && linear::voltage_limit_is_optimal(lin_op, m.w_pos, case_ii);
        const bool ok = voltage_first ? (try_voltage_limit(true) || try_mtpa() || try_voltage_limit(false))
                                      : (try_mtpa() || try_voltage_limit(false));
        if (!ok) converged = false;  // at the edge of reach: keep the limit point
        if (T_red == 0.0) region = Region::zero_torque;
    }
    CurrentCommand cmd;
    cmd.i_d = p.i_d;
    cmd.i_q = p.i_q;
    cmd.region = region;
    cmd.torque = kT * (T_red < T_top ? flux.reduced_torque(p.i_d, p.i_q) : T_red_top);
    cmd.torque_max = kT * T_top;
    cmd.iterations = m.iterations;
    cmd.converged = converged;
    return cmd;
}

}  // namespace ipmsm
