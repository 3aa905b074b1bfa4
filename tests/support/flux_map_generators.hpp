// Flux maps made from formulas, for the tests and the benchmarks (not part of the FMUs): a linear
// machine, and one whose q axis saturates hard.
#pragma once

#include "machine/flux_map.hpp"

namespace ipmsm {

// The map of a linear machine psi_d = L_d i_d + psi_m, psi_q = L_q i_q on an n x n grid
// spanning [-i_range, i_range] on both axes.
FluxMapTable linear_flux_map(double L_d, double L_q, double psi_m, double i_range, int n);

// A q axis that levels off hard (test and benchmark machines): psi_q = L_q i_q / sqrt(1 + (i_q/I_s)^2),
// psi_d = psi_m (1 - cross y^2 / (1 + y^2)) + L_d i_d with y = i_q / I_ref (cross-saturation lowers
// the magnet flux by up to `cross`), on linear_flux_map's grid. Not reciprocal: for the controller.
FluxMapTable saturating_flux_map(double L_d, double L_q, double psi_m, double I_s, double cross, double I_ref,
                                 double i_range, int n);

}  // namespace ipmsm
