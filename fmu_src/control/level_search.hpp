// The robust search for the least-current command: along the torque's level curve s T' = T*, the
// current magnitude as a function of the angle, r(theta) (the first crossing of the level along
// the ray at theta), minimised over the angles whose point is within the voltage limit. Needs no
// derivative of the map beyond the torque's along a ray, so it holds where Newton on the
// optimality conditions does not: coarse grids whose spline makes r(theta) flat with shallow
// ripples (the Prius map's MTPA valley, 10/20 A grid), noisy measured data, torque surfaces with
// kinks. Its resolution comes from the map: rays at the current circles' angles (CurrentCircles)
// bracket the candidates, and around each candidate further rays are cast at a spacing of a
// fraction of the map's grid spacing before a golden-section (interior minimum) or bisection
// (where the voltage limit cuts the level curve) polish to rounding level.
// Slow (tens of microseconds): what takes over where the command check (command_check.hpp) fails.
#pragma once

#include "control/current_circles.hpp"
#include "machine/machine.hpp"
#include "machine/magnet_flux.hpp"

namespace ipmsm::level_search {

struct Result {
    CurrentPoint point{0.0, 0.0};
    Region region = Region::mtpa;  // mtpa (interior minimum) or voltage_limit (on the voltage limit)
    bool found = false;
    int evaluations = 0;  // map evaluations used
};

// The smallest grid spacing of the map, A: the scale on which its spline can bend.
double grid_resolution(const FluxMap& map);

// The least |i| with s T'(i) = T_red (T_red > 0; s = +-1 the torque's sign), |i| <= I_max and
// |v| <= V_max at speed lim.omega. Ties between points of equal current (within a relative
// kTieTolerance) go to the one with i_d <= 0; with left_half, only points with i_d <= 0 are
// searched (docs/controller.md, "One branch where optima tie").
Result least_current(const MagnetFlux& flux, const CurrentCircles& circles, double s, double T_red,
                     const OperatingLimits& lim, double R_s, double resolution_A, bool left_half);

// Relative difference of current below which two optima tie.
constexpr double kTieTolerance = 1e-9;

}  // namespace ipmsm::level_search
