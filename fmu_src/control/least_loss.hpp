// Least-loss commands on the flux map (docs/spec/MATH.md, "Least-loss control"): for a shaft
// torque T* (signed), the current with the least drive loss P_cu + P_fe + P_inv
// (losses/drive_loss.hpp) on the curve T_e(i) - P_fe(i)/w_m = T*, within |i| <= I_max and
// |v| <= V_max; and T_max, the most shaft torque within the limits.
//
// How (each step exact on the map, Newton with the map's second derivatives):
//  1. T_max from the least-current solver's T_max point (the most electromagnetic torque): Newton
//     on the shaft torque's conditions with the same active limits (current circle, voltage
//     limit, or their corner); and, since the drag can make another maximum the largest (a
//     measured map's torque along the current circle can have two within 0.02 % of each other),
//     Newton on the current circle from each of its samples within the voltage limit whose shaft
//     torque comes within 1 % of the best found, and on the corner from where the circle crosses
//     the limit. Each result verified a local maximum (KKT multipliers' signs), the largest wins;
//     where none is, the robust search (3.) for the largest shaft torque on the sampled circles,
//     polished the same way.
//  2. Below T_max, the global search: the constant-shaft-torque curve's crossings of the sampled
//     current circles and of their rays (CurrentCircles: the map's resolution), each crossing's
//     loss, circles beyond the best crossing's loss skipped (no point of current r loses less than
//     the copper and inverter loss of r alone). The best crossings of distinct stretches of the
//     curve seed Newton on the stationarity condition grad P x grad T_shaft = 0 (interior), or the
//     curve's intersection with the voltage limit or the current circle where the interior point
//     breaks a limit; the least exact loss of the points that hold the limits wins. Then a walk
//     along the curve about it in steps of a fraction of the map's grid spacing (the loss along
//     the curve ripples on a coarse grid): a point that loses less seeds Newton again.
//  3. The check: the command's shaft torque on the map, its limits, and no sampled crossing of the
//     curve whose exact loss (projected onto the curve) is less: the search of 2. is global at the
//     circles' resolution, and the check compares its every stretch with the command.
// Magnet-free machines: mirror optima tie, the command keeps i_d <= 0 (as least current does).
#pragma once

#include <cmath>
#include <memory>
#include <vector>

#include "control/current_circles.hpp"
#include "losses/drive_loss.hpp"
#include "machine/machine.hpp"
#include "machine/magnet_flux.hpp"

namespace ipmsm {

struct LeastLossResult {
    CurrentCommand cmd;  // torque, torque_max: shaft torques (N.m; torque_max >= 0)
    LossSplit loss;      // at the command
    bool check_passed = true;
    bool searched = false;  // the robust search ran
    int evaluations = 0;    // map evaluations (Newton steps and samples)
};

class LeastLoss {
public:
    LeastLoss(std::shared_ptr<const FluxMap> map, int pole_pairs, bool magnet_free);

    // T_ref: the shaft torque asked (signed). em_top: the least-current solver's command at its
    // T_max for the same side and conditions (the seed of T_max).
    // hint (optional): a point near the curve (the least-current command for T_ref), polished
    // first so that its exact loss bounds the search.
    LeastLossResult solve(double T_ref, const OperatingLimits& lim, const MagnetFlux& flux, const DriveLoss& loss,
                          const CurrentCommand& em_top, const CurrentPoint* hint = nullptr);

    // The loss and shaft torque of any command (P_loss_cmd for either objective).
    static LossSplit loss_at(const MagnetFlux& flux, const DriveLoss& loss, int pole_pairs, double i_d, double i_q);

    // The scan below T_max visits only the stretches of the circles whose shaft-torque bounds
    // include T* (docs/spec/MATH.md, "Least-loss control"); the reference scan (tests) visits them
    // all: the same crossings, the same command.
    void set_reference_scan(bool on) { reference_scan_ = on; }

    // Bounds of a quantity over a set of circle samples.
    struct Interval {
        double lo = 0, hi = 0;
    };
    // The drag P_fe(|psi|^2) / w_m of every sample of `circle` (the whole circle's ranges), at the
    // magnet shift; iron loss non-decreasing in |psi|^2 (k_h, k_e >= 0, alpha > 0).
    static Interval drag_bounds(const CurrentCircles::Arc& circle, double shift, const IronLossModel& iron, double f,
                                double w_m);
    // The shaft torque kT (T'_0 + shift i_q) - drag of every sample of `stretch`, given the drag's
    // bounds over them (widened by the rounding of the samples' own sums).
    static Interval stretch_torque_bounds(const CurrentCircles::Arc& stretch, double kT, double shift,
                                          const Interval& drag);

    // Tolerances: shaft torque relative to T_max, loss relative (the check's, against the crossings).
    static constexpr double kTorqueTolerance = 1e-9;
    static constexpr double kLossTolerance = 1e-7;
    // A table's command (objective 1, methods 2 and 3) may lose this much more than the exact one
    // (relative): the 0.01 %.
    static constexpr double kTableLossTolerance = 1e-4;

private:
    const CurrentCircles& circles(double I_max);
    // The least |psi|^2 sampled on each circle, for any magnet shift within kShiftStep of `shift`
    // rounded to it (cached: recomputed when the rounded shift or the circles change).
    static constexpr double kShiftStep = 1e-4;  // Wb
    const std::vector<double>& least_flux_sq(const CurrentCircles& C, double shift);
    std::vector<double> psi2_min_;
    double psi2_shift_ = NAN;
    const CurrentCircles* psi2_circles_ = nullptr;
    std::shared_ptr<const FluxMap> map_;
    double resolution_;  // the map's smallest grid spacing, A (level_search::grid_resolution)
    int pole_pairs_;
    bool magnet_free_;
    std::shared_ptr<const CurrentCircles> circles_;
    bool reference_scan_ = false;
};

}  // namespace ipmsm
