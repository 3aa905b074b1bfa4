// The inverse flux map i_d(psi_d, psi_q), i_q(psi_d, psi_q), for the plant: it integrates the
// flux linkages as states and needs the currents (and d i / d psi for the solver's Jacobian).
//
// What is inverted is the map regularised beyond its legal box B (operating_region.hpp: a
// grid-aligned box on which the incremental inductance matrix L = d psi / d i is a P-matrix,
// L_dd > 0, L_qq > 0, det L > 0; by default the whole grid): inside B the forward spline
// (FluxMap::eval); beyond B, with P(i) the nearest point of B (i clamped to it),
//
//     psi_d(i) = psi_d(P(i)) + L_dd(P(i)) (i_d - P_d(i)),   psi_q(i) = psi_q(P(i)) + L_qq(P(i)) (i_q - P_q(i)).
//
// Beyond an i_d edge the Jacobian is [[L_dd(P), *], [0, L_qq(P)]], beyond an i_q edge
// [[L_dd(P), 0], [*, L_qq(P)]], beyond a corner diag(L_dd, L_qq) of the corner: a P-matrix by
// construction, whatever the map does beyond B (data that fold, a cross-saturated map's tangent
// continuation that would fold: its off-diagonal growth cannot change a triangular determinant).
// Across B's edges every convex combination of the two sides' Jacobians is a P-matrix too
// (det = a det_inside + (1 - a) L_dd L_qq). A continuous map whose (generalised) Jacobian is a
// P-matrix on the whole plane is injective (Gale & Nikaido, Math. Annalen 159, 1965), and it
// grows at least linearly with the distance from B, so every flux linkage has exactly one
// current: transients past the grid run. The self-inductances are continuous across B's edges,
// the cross terms drop to zero beyond (a first-order continuation of the saturated edge).
//
// eval() is exact: it inverts the regularised map by Newton's method to rounding, starting from
// a table. G = (d psi / d i)^-1 at the solution.
//
// The table (the start guess): on a uniform rectangular psi grid covering the bounding box of
// the image of B, each node's currents from a damped Newton inversion, then the same C2 bicubic
// spline (bicubic_spline.hpp). Nodes of the box that are images of currents beyond B (its
// corners: the image is a curved quadrilateral) are inverted on the continuation
// (outside_nodes(), max_outside_A()). Newton converges from the table's guess in 1-3 steps inside
// the image (2-3 forward evaluations per eval()); where it does not, a damped Newton search from
// the table's guess and then from the node of B with the nearest fluxes (a k-d tree,
// nearest_point.hpp: O(log N)) takes over; where none converges the currents are NaN.
//
// The error is measured, not assumed: at construction, eval() and the table alone are checked
// against the currents at the centre of every current-grid cell in B (known exactly: their
// fluxes are the forward map's there): max_error_A(), max_table_error_A().
//
// Magnet temperature: a PM flux changed by delta_psi_m shifts the forward map to
// psi_d(i) + delta_psi_m, so its inverse is i(psi_d - delta_psi_m, psi_q): pass the shifted
// psi_d (or use the three-argument eval).
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include <optional>

#include "machine/flux_map.hpp"
#include "machine/nearest_point.hpp"
#include "machine/operating_region.hpp"
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
    // cell, at most 150 cells whatever the current grid (each cell holds 32 doubles).
    int n_psi_d = 0, n_psi_q = 0;
    // Extra width of the psi box on each side, as a fraction of its width.
    double margin = 0.0;
    // The legal box B (MapAcceptance::legal): the map is used inside, continued beyond (above).
    // Unset: the whole grid.
    std::optional<CurrentBox> legal;
};

class InverseFluxMap {
public:
    // Keeps a copy of the map (eval() inverts it). Throws FluxMapError, saying where, if the map
    // is not legal in B (map_defects(): a grid line not monotone, or L not a P-matrix at a node,
    // an edge's or a cell's midpoint: the currents would not be a function of the fluxes), if
    // its image has no extent, or if no node of the table could be inverted.
    explicit InverseFluxMap(const FluxMap& map, const InverseFluxMapOptions& options = {});

    // The currents at (psi_d, psi_q), exact to rounding; NaN where no current reaches them.
    InverseFluxPoint eval(double psi_d, double psi_q) const;
    // The same currents, Newton started from a guess near them (the plant's: its linearisation's
    // first-order prediction within a step) instead of the table: one forward evaluation where
    // the guess is within the step tolerance. Where Newton does not converge inside the grid
    // from there, eval()'s way.
    InverseFluxPoint eval_near(double psi_d, double psi_q, double i_d_guess, double i_q_guess) const;
    // The regularised forward map that eval() inverts (above): the spline inside B, the
    // continuation beyond.
    FluxPoint forward_eval(double i_d, double i_q) const;
    const CurrentBox& legal() const { return legal_; }
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

    // psi nodes whose currents lie outside B, and the largest distance (A, max norm) by which
    // such a current lies outside it.
    int outside_nodes() const { return outside_nodes_; }
    double max_outside_A() const { return max_outside_; }
    // psi nodes whose inversion failed (filled by a first-order continuation of the inverse from
    // their neighbours; none is expected: the regularised map is onto).
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
    // ... of the regularised map (forward_eval).
    bool invert_regularised(double psi_d, double psi_q, double& i_d, double& i_q, double tol,
                            int* iterations = nullptr) const;

private:
    static constexpr int kNewtonSteps = 8;  // from the table's guess, before the damped search
    bool newton(double psi_d, double psi_q, double& i_d, double& i_q, InverseFluxPoint& out) const;
    // The slow path: damped Newton from the table's guess, then from the nearest node.
    InverseFluxPoint search(double psi_d, double psi_q) const;
    void nearest_node(double psi_d, double psi_q, double& i_d, double& i_q) const;
    double outside_legal(double i_d, double i_q) const;  // A, max norm; 0 inside B

    // The construction's phases, in order (inverse_flux_map.cpp).
    struct NodeRange {  // B's grid nodes: j0..j1 along i_d, k0..k1 along i_q
        int j0, j1, k0, k1;
    };
    struct PsiBox {  // the table's flux box, and the extent of B's image (before the margin)
        double d_min, d_max, q_min, q_max, width_d, width_q;
    };
    struct PsiTable {  // the table's nodes and their currents, where inverted
        std::vector<double> psi_d, psi_q, i_d, i_q;
        std::vector<char> inverted;
    };
    NodeRange snap_legal_box(const FluxMap& map, const CurrentBox& legal);
    static void check_one_to_one(const FluxMap& map, const NodeRange& b, const CurrentBox& legal);
    static PsiBox image_box(const FluxMap& map, const NodeRange& b, double margin);
    static PsiTable psi_grid(const FluxMap& map, const NodeRange& b, const PsiBox& box,
                             const InverseFluxMapOptions& options);
    void index_nodes(const FluxMapTable& t, const NodeRange& b, const PsiBox& box);
    void invert_nodes(PsiTable& table);
    void continue_unreachable(PsiTable& table) const;
    void measure_errors(const FluxMap& map, const NodeRange& b);

    FluxMap forward_;
    CurrentBox legal_;
    NearestPoint2D nodes_;                     // the grid nodes in B, at their fluxes / psi_width_
    std::vector<double> node_i_d_, node_i_q_;  // their currents
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
        const FluxPoint p = forward_eval(i_d, i_q);
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

inline FluxPoint InverseFluxMap::forward_eval(double i_d, double i_q) const {
    const double cd = std::min(std::max(i_d, legal_.i_d_min), legal_.i_d_max);
    const double cq = std::min(std::max(i_q, legal_.i_q_min), legal_.i_q_max);
    const double ed = i_d - cd, eq = i_q - cq;  // how far beyond B (0 inside)
    if (ed == 0.0 && eq == 0.0) return forward_.eval(i_d, i_q);
    const FluxPoint2 p = forward_.eval2(cd, cq);
    FluxPoint r;
    r.psi_d = p.psi_d + p.L_dd * ed;
    r.psi_q = p.psi_q + p.L_qq * eq;
    r.L_dd = p.L_dd;
    r.L_qq = p.L_qq;
    // A cross derivative survives only along an edge (P moves with the tangential current).
    r.L_dq = eq == 0.0 ? p.L_dq + p.psi_d_dq * ed : 0.0;
    r.L_qd = ed == 0.0 ? p.L_qd + p.psi_q_dq * eq : 0.0;
    return r;
}

inline InverseFluxPoint InverseFluxMap::eval(double psi_d, double psi_q) const {
    SplineValue s[2];
    spline_.eval<2>(psi_d, psi_q, s);
    double i_d = s[0].f, i_q = s[1].f;
    InverseFluxPoint out;
    if (newton(psi_d, psi_q, i_d, i_q, out)) return out;  // the only preimage (above)
    return search(psi_d, psi_q);
}

inline InverseFluxPoint InverseFluxMap::eval_near(double psi_d, double psi_q, double i_d_guess,
                                                  double i_q_guess) const {
    InverseFluxPoint out;
    if (std::isfinite(i_d_guess) && std::isfinite(i_q_guess) && newton(psi_d, psi_q, i_d_guess, i_q_guess, out))
        return out;
    return eval(psi_d, psi_q);
}

}  // namespace ipmsm
