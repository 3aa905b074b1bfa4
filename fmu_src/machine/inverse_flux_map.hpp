// The inverse flux map i_d(psi_d, psi_q), i_q(psi_d, psi_q), for the plant: it integrates the
// flux linkages as states and needs the currents (and d i / d psi for the solver's Jacobian)
// without inverting anything at run time.
//
// Built once from a FluxMap: on a uniform rectangular psi grid covering the bounding box of the
// image of the current grid, each node's currents come from a damped Newton inversion of the
// forward spline (converged to rounding), and the same C2 bicubic spline (bicubic_spline.hpp)
// interpolates them. Nodes of the box that are not images of the current grid (its corners:
// the image is a curved quadrilateral) are inverted on the forward map's linear extrapolation,
// so the table is the inverse of the forward map as FluxMap::eval defines it everywhere;
// outside_nodes() and max_outside_A() report how many there were and how far out they went.
// Outside the psi box the inverse is continued linearly like every spline here.
//
// Magnet temperature: a PM flux changed by delta_psi_m shifts the forward map to
// psi_d(i) + delta_psi_m, so its inverse is i(psi_d - delta_psi_m, psi_q): pass the shifted
// psi_d (or use the three-argument eval). One table serves every temperature; the psi box
// simply moves by delta_psi_m and the linear continuation covers the (small) shift.
#pragma once

#include <vector>

#include "numerics/bicubic_spline.hpp"
#include "machine/flux_map.hpp"

namespace ipmsm {

// Currents at one flux linkage, with the inverse incremental inductances d i / d psi, 1/H.
struct InverseFluxPoint {
    double i_d, i_q;    // A
    double G_dd, G_dq;  // d i_d / d psi_d, d i_d / d psi_q
    double G_qd, G_qq;  // d i_q / d psi_d, d i_q / d psi_q
};

struct InverseFluxMapOptions {
    // psi grid nodes per axis; 0: automatic: psi spacing at most half the smallest flux step
    // between adjacent current-grid nodes along that axis, at least three psi cells per current
    // cell, at most 300 cells (each cell holds 32 doubles).
    int n_psi_d = 0, n_psi_q = 0;
    // Extra width of the psi box on each side, as a fraction of its width.
    double margin = 0.0;
};

class InverseFluxMap {
public:
    // Throws FluxMapError if some psi node cannot be inverted (the forward map is not
    // invertible there: a non-positive Jacobian determinant, e.g. a non-monotone map).
    explicit InverseFluxMap(const FluxMap& map, const InverseFluxMapOptions& options = {});

    InverseFluxPoint eval(double psi_d, double psi_q) const;
    // The machine whose PM flux is delta_psi_m above the map's (magnet temperature).
    InverseFluxPoint eval(double psi_d, double psi_q, double delta_psi_m) const {
        return eval(psi_d - delta_psi_m, psi_q);
    }

    double psi_d_min() const { return spline_.x().front(); }
    double psi_d_max() const { return spline_.x().back(); }
    double psi_q_min() const { return spline_.y().front(); }
    double psi_q_max() const { return spline_.y().back(); }
    int n_psi_d() const { return static_cast<int>(spline_.x().size()); }
    int n_psi_q() const { return static_cast<int>(spline_.y().size()); }

    // psi nodes whose currents lie outside the forward map's current grid, and the largest
    // distance (A, max norm) by which such a current lies outside it.
    int outside_nodes() const { return outside_nodes_; }
    double max_outside_A() const { return max_outside_; }
    // Largest Newton residual |psi(i) - psi_node| (max norm, Wb) over the nodes.
    double max_residual() const { return max_residual_; }

    const BicubicSpline2D& spline() const { return spline_; }  // fields 0: i_d, 1: i_q
    std::size_t memory_bytes() const { return spline_.memory_bytes(); }

    // One exact inversion of the forward map: finds i with map.eval(i) = psi by damped Newton
    // from (i_d, i_q) (updated in place). Returns false if it did not converge. tol: max-norm
    // residual in Wb. iterations (optional): Newton steps taken.
    static bool invert(const FluxMap& map, double psi_d, double psi_q, double& i_d, double& i_q,
                       double tol, int* iterations = nullptr);

private:
    BicubicSpline2D spline_;
    int outside_nodes_ = 0;
    double max_outside_ = 0;
    double max_residual_ = 0;
};

inline InverseFluxPoint InverseFluxMap::eval(double psi_d, double psi_q) const {
    SplineValue s[2];
    spline_.eval<2>(psi_d, psi_q, s);
    return InverseFluxPoint{s[0].f, s[1].f, s[0].fx, s[0].fy, s[1].fx, s[1].fy};
}

}  // namespace ipmsm
