// Which flux maps the FMUs accept: the one rule (docs/maps.md, "Where a map must be legal").
//
// A real map (FEM export, measurement) is often not monotone or invertible everywhere: psi_d
// falls with i_d, or the incremental inductances fold, at edges the drive never reaches. The map
// is legal at a point when its incremental inductance matrix L = d psi / d i is a P-matrix there
// (L_dd > 0, L_qq > 0, det L > 0): then the currents are a function of the flux linkages
// (Gale & Nikaido 1965). It is checked on the tabulated data (psi_d rising in i_d along every
// i_q grid line, psi_q in i_q along every i_d line) and on the spline at every node, edge
// midpoint and cell centre.
//
// The operating region: the currents within the I_max circle; with a magnet (psi_m at least
// kMagnetFraction of the map's largest |psi_d|) only i_d <= 0 of it, since every command of a PM
// machine demagnetises (MATH.md: MTPA, field weakening and MTPV all have i_d <= 0). Its bounding
// box, widened by kOperatingMargin I_max on every side (the current regulator's transients; for
// the plant, the fluxes those currents reach) and cut to the grid, is the required box: a defect
// there is refused, naming where and what to do; defects beyond it are accepted with one warning.
// The legal box is the largest grid-aligned box that contains the required box and no defect: the
// plant uses the map inside it and its positive-definite continuation beyond
// (inverse_flux_map.hpp).
#pragma once

#include <string>
#include <vector>

#include "machine/flux_map.hpp"

namespace ipmsm {

// Margin around the operating region's bounding box, as a fraction of I_max: the room given to
// current transients beyond the commanded currents. A PI current loop tuned to the modulus
// optimum (Kessler 1955, the usual tuning) overshoots a step by 4.3 %; the margin is twice that,
// rounded up (docs/maps.md).
inline constexpr double kOperatingMargin = 0.1;
// A machine has a magnet when psi_d(0, 0) is at least this fraction of the map's largest |psi_d|
// (a magnet-free map's psi_d(0, 0) is zero to its noise; docs/maps.md).
inline constexpr double kMagnetFraction = 0.01;
// The map folds where the determinant of the incremental inductances is at most this fraction of
// L_dd L_qq: zero to the spline's rounding (some 4500 times the rounding unit of a double, 2.2e-16).
inline constexpr double kFoldRelative = 1e-12;

// A box of currents, A (closed).
struct CurrentBox {
    double i_d_min = 0, i_d_max = 0, i_q_min = 0, i_q_max = 0;
    bool contains(double i_d, double i_q) const {
        return i_d >= i_d_min && i_d <= i_d_max && i_q >= i_q_min && i_q <= i_q_max;
    }
};

// "i_d in [a, b] A, i_q in [c, d] A"
std::string describe(const CurrentBox& box);

struct OperatingRegion {
    double I_max = 0;     // A
    bool magnet = true;   // psi_d(0, 0) >= kMagnetFraction max |psi_d|: only i_d <= 0 is commanded
    CurrentBox required;  // the operating region's bounding box with the margin, cut to the grid
};

OperatingRegion operating_region(const FluxMap& map, double I_max);

// Where the map is not legal: what (in words, with currents and values) and the grid nodes
// spanned, as indices into the doubled lattice of nodes and midpoints (node j at 2 j).
struct MapDefect {
    std::string what;
    int d0, d1, q0, q1;  // closed lattice index ranges
};

// Every defect of the map, data first, in grid order (at most max_defects; the count is exact).
struct MapDefects {
    std::vector<MapDefect> list;
    std::size_t count = 0;
};
MapDefects map_defects(const FluxMap& map, std::size_t max_defects = 64);

struct MapAcceptance {
    OperatingRegion region;
    CurrentBox legal;     // the largest defect-free grid box containing region.required (greedy)
    std::size_t defects;  // how many, all outside region.required
    std::string warning;  // one message naming them and the legal box; empty when there are none
};

// The rule. Throws FluxMapError naming the map, the first defect in the required box, the region
// and what to do (repair the map, or lower I_max) when one lies there.
MapAcceptance accept_flux_map(const FluxMap& map, double I_max, const std::string& map_name);

}  // namespace ipmsm
