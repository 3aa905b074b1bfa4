// The inverse flux map i_d(psi_d, psi_q), i_q(psi_d, psi_q), for the plant: it integrates the
// flux linkages as states and needs the currents (and d i / d psi for the solver's Jacobian).
//
// eval() is exact: it inverts the forward spline (FluxMap::eval, with its linear continuation
// outside the current grid) by Newton's method to rounding, starting from a table. So the
// currents are the map's own inverse at every flux linkage the map (or its continuation)
// reaches, whatever the grid or the saturation; G = (d psi / d i)^-1 at the solution.
//
// The table (the start guess): on a uniform rectangular psi grid covering the bounding box of
// the image of the current grid, each node's currents from a damped Newton inversion, then the
// same C2 bicubic spline (bicubic_spline.hpp). Nodes of the box that are images of currents
// outside the grid (its corners: the image is a curved quadrilateral) are inverted on the
// forward map's linear continuation (outside_nodes(), max_outside_A()); nodes that not even the
// continuation reaches (a strongly cross-saturated map's continuation can lose monotonicity far
// out) get a first-order continuation of the inverse from their nearest inverted neighbour
// (unreachable_nodes()). Newton then converges from the table's guess in 1-3 steps inside the
// image (2-3 forward evaluations per eval()). Where it does not, or converges to currents beyond
// the grid (where the continuation may fold, giving the same fluxes more than one preimage), a
// damped Newton search from the table's guess and from the grid node with the nearest fluxes
// takes over and keeps the preimage nearest the grid; where no search converges the currents
// are NaN: no current gives those flux linkages on the map or its continuation.
//
// The error is measured, not assumed: at construction, eval() and the table alone are checked
// against the currents at the centre of every current-grid cell (known exactly: their fluxes
// are the forward map's there): max_error_A(), max_table_error_A().
//
// Magnet temperature: a PM flux changed by delta_psi_m shifts the forward map to
// psi_d(i) + delta_psi_m, so its inverse is i(psi_d - delta_psi_m, psi_q): pass the shifted
// psi_d (or use the three-argument eval).
#pragma once

#include <cmath>
#include <vector>

#include "machine/flux_map.hpp"
#include "numerics/bicubic_spline.hpp"

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
    // cell, at most 150 cells (each cell holds 32 doubles).
    int n_psi_d = 0, n_psi_q = 0;
    // Extra width of the psi box on each side, as a fraction of its width.
    double margin = 0.0;
};

class InverseFluxMap {
public:
    // Keeps a copy of the map (eval() inverts it). Throws FluxMapError, saying where, if the map
    // folds on its grid (the incremental inductance matrix has a determinant <= 0 at a node or a
    // cell's or edge's midpoint: the currents would not be a function of the fluxes), if its
    // image has no extent, or if no node of the table could be inverted.
    explicit InverseFluxMap(const FluxMap& map, const InverseFluxMapOptions& options = {});

    // The currents at (psi_d, psi_q), exact to rounding; NaN where no current reaches them.
    InverseFluxPoint eval(double psi_d, double psi_q) const;
    // The same currents, Newton started from a guess near them (the plant's: its linearisation's
    // first-order prediction within a step) instead of the table: one forward evaluation where
    // the guess is within the step tolerance. Where Newton does not converge inside the grid
    // from there, eval()'s way.
    InverseFluxPoint eval_near(double psi_d, double psi_q, double i_d_guess, double i_q_guess) const;
    // The table's interpolated start guess alone (for the benchmark and the tests).
    InverseFluxPoint table(double psi_d, double psi_q) const;
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
    // psi nodes that no current reaches (filled by continuation of the inverse, above).
    int unreachable_nodes() const { return unreachable_nodes_; }
    // Largest Newton residual |psi(i) - psi_node| (max norm, Wb) over the inverted nodes.
    double max_residual() const { return max_residual_; }
    // Largest error (A, max norm) of eval() and of the table alone at the currents of the
    // current-grid cells' centres, measured at construction (above).
    double max_error_A() const { return max_error_; }
    double max_table_error_A() const { return max_table_error_; }
    const FluxMap& forward() const { return forward_; }

    const BicubicSpline2D& spline() const { return spline_; }  // fields 0: i_d, 1: i_q
    std::size_t memory_bytes() const { return spline_.memory_bytes(); }

    // One exact inversion of the forward map: finds i with map.eval(i) = psi by damped Newton
    // from (i_d, i_q) (updated in place). Returns false if it did not converge. tol: max-norm
    // residual in Wb. iterations (optional): Newton steps taken.
    static bool invert(const FluxMap& map, double psi_d, double psi_q, double& i_d, double& i_q, double tol,
                       int* iterations = nullptr);

private:
    static constexpr int kNewtonSteps = 8;  // from the table's guess, before the damped search
    bool newton(double psi_d, double psi_q, double& i_d, double& i_q, InverseFluxPoint& out) const;
    bool inside_grid(double i_d, double i_q) const;
    // The slow path: fast = the fast Newton's converged currents, nullptr if it did not converge.
    InverseFluxPoint search(double psi_d, double psi_q, const double* fast) const;
    void nearest_node(double psi_d, double psi_q, double& i_d, double& i_q) const;
    double outside_grid(double i_d, double i_q) const;  // A, max norm; 0 inside

    FluxMap forward_;
    BicubicSpline2D spline_;
    double step_tol_ = 0;           // A: a Newton correction this small leaves rounding-level error
    double flux_tol_ = 0;           // Wb: the damped search's residual
    double psi_width_[2] = {1, 1};  // Wb: the image's extent, to compare flux distances
    int outside_nodes_ = 0, unreachable_nodes_ = 0;
    double max_outside_ = 0;
    double max_residual_ = 0;
    double max_error_ = 0, max_table_error_ = 0;
};

inline InverseFluxPoint InverseFluxMap::table(double psi_d, double psi_q) const {
    SplineValue s[2];
    spline_.eval<2>(psi_d, psi_q, s);
    return InverseFluxPoint{s[0].f, s[1].f, s[0].fx, s[0].fy, s[1].fx, s[1].fy};
}

// Newton on psi(i) = psi* from (i_d, i_q): quadratic; a correction below step_tol_ (1e-9 of the
// grid's extent) leaves an error of its square, far below rounding of i. True when it converged
// (out: the currents and G there).
inline bool InverseFluxMap::newton(double psi_d, double psi_q, double& i_d, double& i_q, InverseFluxPoint& out) const {
    for (int k = 0; k < kNewtonSteps; ++k) {
        const FluxPoint p = forward_.eval(i_d, i_q);
        const double det = p.L_dd * p.L_qq - p.L_dq * p.L_qd;
        if (!(std::abs(det) > 0) || !std::isfinite(det)) return false;
        const double G_dd = p.L_qq / det, G_dq = -p.L_dq / det, G_qd = -p.L_qd / det, G_qq = p.L_dd / det;
        const double rd = psi_d - p.psi_d, rq = psi_q - p.psi_q;
        const double dd = G_dd * rd + G_dq * rq, dq = G_qd * rd + G_qq * rq;
        i_d += dd;
        i_q += dq;
        if (std::abs(dd) <= step_tol_ && std::abs(dq) <= step_tol_) {
            out = InverseFluxPoint{i_d, i_q, G_dd, G_dq, G_qd, G_qq};
            return true;
        }
    }
    return false;
}

inline bool InverseFluxMap::inside_grid(double i_d, double i_q) const {
    return i_d >= forward_.i_d_min() && i_d <= forward_.i_d_max() && i_q >= forward_.i_q_min() &&
           i_q <= forward_.i_q_max();
}

inline InverseFluxPoint InverseFluxMap::eval(double psi_d, double psi_q) const {
    SplineValue s[2];
    spline_.eval<2>(psi_d, psi_q, s);
    double i_d = s[0].f, i_q = s[1].f;
    InverseFluxPoint out;
    if (!newton(psi_d, psi_q, i_d, i_q, out)) return search(psi_d, psi_q, nullptr);
    if (inside_grid(out.i_d, out.i_q)) return out;
    const double fast[2] = {out.i_d, out.i_q};  // beyond the grid: is there a preimage nearer to it?
    return search(psi_d, psi_q, fast);
}

inline InverseFluxPoint InverseFluxMap::eval_near(double psi_d, double psi_q, double i_d_guess,
                                                  double i_q_guess) const {
    InverseFluxPoint out;
    if (std::isfinite(i_d_guess) && std::isfinite(i_q_guess) && newton(psi_d, psi_q, i_d_guess, i_q_guess, out) &&
        inside_grid(out.i_d, out.i_q))
        return out;
    return eval(psi_d, psi_q);
}

}  // namespace ipmsm
