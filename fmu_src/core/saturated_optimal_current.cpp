#include "saturated_optimal_current.hpp"

#include <algorithm>
#include <cmath>

#include "map_newton.hpp"

namespace ipmsm {
namespace {

// Below this current an apparent inductance (flux / current) is ill-defined: use the incremental one.
constexpr double kApparentMinCurrent_A = 1e-3;
// Relative slack on the limits for points computed on a limit.
constexpr double kLimitSlack = 1e-9;

double sign_of(double T) { return T < 0 ? -1.0 : 1.0; }

}  // namespace

SaturatedOptimalCurrent::SaturatedOptimalCurrent(std::shared_ptr<const FluxMap> map, int pole_pairs)
    : map_(std::move(map)), pole_pairs_(pole_pairs) {
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
            cmd = linear::optimal_current(nominal_machine(R_s, psi_d_shift), pole_pairs_, T_ref, lim);
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
            c = linear::optimal_current(apparent_machine(flux, i_d, i_q, R_s), pole_pairs_, T, lim);
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

CurrentCommand SaturatedOptimalCurrent::solve_optimal(double T_ref, const OperatingLimits& lim,
                                                      double R_s, const MagnetFlux& flux) {
    using map_newton::Problem;
    using map_newton::System;
    const double s = sign_of(T_ref);
    const double kT = torque_factor(pole_pairs_);
    const double V2 = lim.V_max * lim.V_max * (1.0 + kLimitSlack);
    const double I2 = lim.I_max * lim.I_max * (1.0 + kLimitSlack);
    int iterations = 0;
    bool converged = true;
    auto newton = [&](System sys, double T_red, linear::Point seed) {
        const Problem P{sys, lim.omega, R_s, T_red, lim.V_max, lim.I_max};
        const auto r = map_newton::solve(flux, P, seed.i_d, seed.i_q);
        iterations += r.iterations;
        return r;
    };
    auto current_sq = [](double a, double b) { return a * a + b * b; };

    // Ferrari seeds from the machine linearised (apparent inductances) at the last solutions.
    // Seeds are computed for T >= 0 (linear:: functions) and mirrored: (omega, i_q) -> (s omega, s i_q).
    const double w_pos = s * lim.omega;
    const LinearMachine lin_op = apparent_machine(flux, memory.op_i_d, s * std::abs(memory.op_i_q), R_s);
    const LinearMachine lin_lim =
        memory.has_limit ? apparent_machine(flux, memory.limit_i_d, s * std::abs(memory.limit_i_q), R_s) : lin_op;
    auto mirrored = [s](linear::Point p) { return linear::Point{p.i_d, s * p.i_q}; };

    // 1. The largest torque reachable now (this torque sign), on the map.
    CurrentCommand cmd;
    linear::Point top{};
    double T_top = 0;  // reduced, >= 0
    Region top_region = Region::zero_torque;
    {
        const auto r1 = newton(System::mtpa_at_current, 0, mirrored(linear::mtpa_at_current(lin_lim, lim.I_max)));
        if (r1.converged && map_newton::voltage_sq(flux, lim.omega, R_s, r1.i_d, r1.i_q) <= V2) {
            top = {r1.i_d, r1.i_q};
            top_region = Region::mtpa;
        } else {
            linear::Point seed;
            bool found = false;
            if (linear::mtpv(lin_lim, w_pos, lim.V_max, seed)) {
                const auto r2 = newton(System::mtpv, 0, mirrored(seed));
                if (r2.converged && current_sq(r2.i_d, r2.i_q) <= I2) {
                    top = {r2.i_d, r2.i_q};
                    top_region = Region::mtpv;
                    found = true;
                }
            }
            if (!found && linear::current_voltage_intersection(lin_lim, w_pos, lim.V_max, lim.I_max, seed)) {
                const auto r3 = newton(System::current_voltage, 0, mirrored(seed));
                if (r3.converged) {
                    top = {r3.i_d, r3.i_q};
                    top_region = Region::current_and_voltage_limit;
                    found = true;
                }
            }
            if (!found) {
                // No exact limit point on the map: above the maximum speed, or Newton failed.
                // Fall back to the paper's recursion for this step.
                CurrentCommand fb = solve_recursive(T_ref, lim, R_s, flux);
                fb.iterations += iterations;
                fb.converged = false;
                return fb;
            }
        }
        T_top = std::max(0.0, s * flux.reduced_torque(top.i_d, top.i_q));
        memory.limit_i_d = top.i_d;
        memory.limit_i_q = top.i_q;
        memory.has_limit = true;
    }
    cmd.torque_max = kT * T_top;

    // 2. The command: clamped to T_max, else MTPA, else the voltage ellipse (Case ii).
    const double T_red = std::abs(T_ref) / kT;
    linear::Point p = top;
    Region region = top_region;
    if (T_red < T_top) {
        // The Ferrari seed's region says which conditions to solve first; the a-priori test on
        // the map confirms it (or sends us to the other).
        const double target = s * T_red;
        const CurrentCommand seed = linear::optimal_current(lin_op, pole_pairs_, s * T_red * kT, {w_pos * s, lim.V_max, lim.I_max});
        auto try_mtpa = [&]() {
            const auto r = newton(System::mtpa, target, mirrored(linear::mtpa(lin_op, T_red)));
            if (!r.converged || map_newton::voltage_sq(flux, lim.omega, R_s, r.i_d, r.i_q) > V2 ||
                current_sq(r.i_d, r.i_q) > I2)
                return false;
            p = {r.i_d, r.i_q};
            region = Region::mtpa;
            return true;
        };
        auto try_voltage_limit = [&](bool must_be_optimal) {
            linear::Point seed_ii{seed.i_d, s * seed.i_q};
            if (seed.region != Region::voltage_limit) {
                const bool have = T_red > 0 ? linear::voltage_limit(lin_op, w_pos, lim.V_max, T_red, seed_ii)
                                            : linear::zero_torque(lin_op, w_pos, lim.V_max, seed_ii);
                if (!have) seed_ii = linear::Point{top.i_d, s * top.i_q};
            }
            const auto r = newton(System::voltage_limit, target, mirrored(seed_ii));
            if (!r.converged || current_sq(r.i_d, r.i_q) > I2) return false;
            if (must_be_optimal && !map_newton::voltage_limit_is_optimal(flux, lim.omega, R_s, r.i_d, r.i_q)) return false;
            p = {r.i_d, r.i_q};
            region = Region::voltage_limit;
            return true;
        };
        const bool ok = seed.region == Region::voltage_limit ? (try_voltage_limit(true) || try_mtpa() || try_voltage_limit(false))
                                                            : (try_mtpa() || try_voltage_limit(false));
        if (!ok) converged = false;  // at the edge of reach: keep the limit point
        if (T_red == 0.0) region = Region::zero_torque;
    }
    cmd.i_d = p.i_d;
    cmd.i_q = p.i_q;
    cmd.region = region;
    cmd.torque = kT * flux.reduced_torque(p.i_d, p.i_q);
    cmd.iterations = iterations;
    cmd.converged = converged;
    return cmd;
}

}  // namespace ipmsm
