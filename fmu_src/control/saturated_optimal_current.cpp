#include "control/saturated_optimal_current.hpp"

#include <algorithm>
#include <cmath>

#include "control/decision.hpp"
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

// The flux map as decision.hpp's View for one solve_optimal() call and one torque sign s: each
// condition is Newton on the map (map_newton.hpp) from Ferrari's point on the machine linearised
// at the last solutions. Points are the map's own (i_q signed like the torque); torque() is
// s T', >= 0 on the side decided. Ferrari's seeds are for T >= 0 on the mirrored problem
// (omega, i_q) -> (s omega, s i_q).
struct MapView {
    MapView(const MagnetFlux& flux, const OperatingLimits& lim, double R_s, double s, const LinearMachine& lin_limit,
            const LinearMachine& lin_command)
        : flux(flux), lim(lim), R_s(R_s), s(s), w_pos(s * lim.omega), lin_limit(lin_limit), lin_command(lin_command),
          V2(lim.V_max * lim.V_max * (1.0 + kLimitSlack)), I2(lim.I_max * lim.I_max * (1.0 + kLimitSlack)) {}

    double torque(CurrentPoint p) const { return s * flux.reduced_torque(p.i_d, p.i_q); }
    bool within_voltage(CurrentPoint p) const { return map_newton::voltage_sq(flux, lim.omega, R_s, p.i_d, p.i_q) <= V2; }
    bool within_current(CurrentPoint p) const { return p.i_d * p.i_d + p.i_q * p.i_q <= I2; }

    bool mtpa_at_current_limit(CurrentPoint& p) {
        return solve(System::mtpa_at_current, 0.0, linear::mtpa_at_current(lin_limit, lim.I_max), p);
    }
    bool mtpv(CurrentPoint& p) {
        linear::Point seed;
        return linear::mtpv(lin_limit, w_pos, lim.V_max, seed) && solve(System::mtpv, 0.0, seed, p) && torque(p) >= 0;
    }
    bool current_voltage_intersection(CurrentPoint& p) {
        linear::Point seed;
        return linear::current_voltage_intersection(lin_limit, w_pos, lim.V_max, lim.I_max, seed) &&
               solve(System::current_voltage, 0.0, seed, p) && torque(p) >= 0;
    }
    bool mtpa(double T_red, CurrentPoint& p) {
        return solve(System::mtpa, T_red, linear::mtpa(lin_command, T_red), p) && within_current(p);
    }
    bool voltage_limit(double T_red, CurrentPoint& p) {
        linear::Point seed;
        if (!linear::voltage_limit(lin_command, w_pos, lim.V_max, T_red, seed)) return false;
        return solve(System::voltage_limit, T_red, seed, p) && within_current(p);
    }
    bool zero_torque(CurrentPoint& p) {
        p = {0.0, 0.0};
        if (within_voltage(p)) return true;
        linear::Point seed;
        return linear::zero_torque(lin_command, w_pos, lim.V_max, seed) && solve(System::voltage_limit, 0.0, seed, p);
    }

    // Newton on `sys` from the mirrored seed, to a point p of the map (T_red >= 0 on this side).
    bool solve(System sys, double T_red, linear::Point seed, CurrentPoint& p) {
        const map_newton::Problem P{sys, lim.omega, R_s, s * T_red, lim.V_max, lim.I_max};
        const auto r = map_newton::solve(flux, P, seed.i_d, s * seed.i_q, kNewtonMaxIterations,
                                         kNewtonStepTolerance * lim.I_max);
        iterations += r.iterations;
        p = {r.i_d, r.i_q};
        return r.converged;
    }

    const MagnetFlux& flux;
    const OperatingLimits& lim;
    const double R_s, s, w_pos;
    const LinearMachine &lin_limit, &lin_command;  // Ferrari's machines for T_max and the command
    const double V2, I2;  // squared limits with slack, for points computed on a limit
    int iterations = 0;
};

}  // namespace

CurrentCommand SaturatedOptimalCurrent::solve_optimal(double T_ref, const OperatingLimits& lim,
                                                      double R_s, const MagnetFlux& flux) {
    const double s = sign_of(T_ref);
    const double kT = torque_factor(pole_pairs_);

    // Ferrari seeds from the machine linearised (apparent inductances) at the last solutions.
    auto linearised_at = [&](double i_d, double i_q) { return apparent_machine(flux, i_d, s * std::abs(i_q), R_s); };
    const LinearMachine lin_limit = memory.has_limit ? linearised_at(memory.limit_i_d, memory.limit_i_q)
                                                     : linearised_at(memory.op_i_d, memory.op_i_q);
    const LinearMachine lin_command = linearised_at(memory.op_i_d, memory.op_i_q);
    MapView view(flux, lim, R_s, s, lin_limit, lin_command);

    // 1. The largest torque reachable now (this torque sign), on the map.
    const decision::Choice top = decision::max_torque(view);
    if (!top.feasible) {
        // No limit point on the map: above the maximum speed, or Newton failed. Fall back to the
        // paper's recursion for this step.
        CurrentCommand fb = solve_recursive(T_ref, lim, R_s, flux);
        fb.iterations += view.iterations;
        fb.converged = false;
        return fb;
    }
    const double T_top = std::max(0.0, view.torque(top.point));  // reduced, >= 0
    memory.limit_i_d = top.point.i_d;
    memory.limit_i_q = top.point.i_q;
    memory.has_limit = true;

    // 2. The command: clamped to T_max, else MTPA, else the voltage limit (Case ii).
    const double T_red = std::abs(T_ref) / kT;
    const decision::Choice c = decision::command(view, T_red, top);
    CurrentCommand cmd;
    cmd.i_d = c.point.i_d;
    cmd.i_q = c.point.i_q;
    cmd.region = c.region;
    cmd.torque = kT * (T_red < T_top ? flux.reduced_torque(c.point.i_d, c.point.i_q) : s * T_top);
    cmd.torque_max = kT * T_top;
    cmd.iterations = view.iterations;
    cmd.converged = T_red >= T_top || c.point.i_d != top.point.i_d || c.point.i_q != top.point.i_q;
    return cmd;
}

}  // namespace ipmsm
