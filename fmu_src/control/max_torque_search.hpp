// The robust search for T_max: the most torque s T'(i) within the current limit |i| <= I_max and
// the voltage limit |v| <= V_max, found without the optimality conditions, so that it holds where
// Newton from the decision's seeds does not (a second local maximum next to the one found, coarse
// grids, kinks). Nested one-dimensional searches: over the radius |i| = r, the most torque on the
// circle of radius r within the voltage limit, H(r) (an interior maximum along the circle, or
// where the voltage limit cuts it); T_max = max over r <= I_max of H(r), which covers the current
// circle, the voltage limit (MTPV) and their corner alike. The map's samples on the current
// circles (CurrentCircles) bracket the candidates; around each, the circle is sampled at a
// fraction of the map's grid spacing (level_search::grid_resolution) before golden section in the
// angle, bisection on the voltage limit and golden section in the radius polish it.
// Slow (some 0.3 to 0.8 ms): what takes over where T_max's check fails
// (docs/controller.md, "T_max: the most torque within the limits").
#pragma once

#include "control/current_circles.hpp"
#include "machine/machine.hpp"
#include "machine/magnet_flux.hpp"

namespace ipmsm::max_torque_search {

struct Result {
    CurrentPoint point{0.0, 0.0};
    double torque = 0;  // s T' at point (reduced, >= 0 where found)
    bool found = false;
    int evaluations = 0;  // map evaluations used
};

// The most s T' (s = +-1, the torque's sign) with |i| <= I_max and |v| <= V_max at speed
// lim.omega; with left_half only i_d <= 0 (the tie convention of magnet-free machines).
// resolution_A: the map's smallest grid spacing.
Result max_torque(const MagnetFlux& flux, const CurrentCircles& circles, double s, const OperatingLimits& lim,
                  double R_s, double resolution_A, bool left_half);

}  // namespace ipmsm::max_torque_search
