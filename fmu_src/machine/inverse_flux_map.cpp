// The inverse flux map: a table of the inverse (Newton on a psi grid, then a spline) as the
// start of an exact Newton inversion at every evaluation.
#include "machine/inverse_flux_map.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

namespace ipmsm {
namespace {

double max_abs(double a, double b) { return std::max(std::abs(a), std::abs(b)); }

// The table is only eval()'s start guess: past 150 cells per axis (5.8 MB on a 51 x 51 map) a
// finer one saves no Newton step that its cache misses do not cost (bench_flux_map: 301 x 301,
// 23 MB, built in 80-95 ms, eval 157-272 ns; 151 x 151, 15-21 ms, 132-189 ns; 101 x 101, 277 ns).
constexpr double kMaxTableCells = 150.0;

template <class Map>
bool damped_newton(const Map& map, double psi_d, double psi_q, double& i_d, double& i_q, double tol, int* iterations,
                   double cap) {
    // Damped Newton on r(i) = psi(i) - psi*, backtracking on the max-norm of r. The step size
    // is also capped (at a quarter of the grid's extent) so that a poor start cannot throw the
    // iterate far into the extrapolated region in one step.
    FluxPoint p = map.eval(i_d, i_q);
    double rd = p.psi_d - psi_d, rq = p.psi_q - psi_q;
    double rn = max_abs(rd, rq);
    int it = 0;
    bool ok = false;
    for (; it < 100; ++it) {
        if (!std::isfinite(rn)) break;
        if (rn <= tol) {
            // Converged: one more full step takes the iterate to rounding level (so that a
            // linear map's inverse is linear to rounding), kept only if it does no harm.
            const double det = p.L_dd * p.L_qq - p.L_dq * p.L_qd;
            if (std::abs(det) > 0 && rn > 0) {
                const double nd = i_d - (p.L_qq * rd - p.L_dq * rq) / det;
                const double nq = i_q - (-p.L_qd * rd + p.L_dd * rq) / det;
                const FluxPoint pn = map.eval(nd, nq);
                if (max_abs(pn.psi_d - psi_d, pn.psi_q - psi_q) <= rn) {
                    i_d = nd;
                    i_q = nq;
                }
            }
            ok = true;
            break;
        }
        const double det = p.L_dd * p.L_qq - p.L_dq * p.L_qd;
        if (!(std::abs(det) > 0) || !std::isfinite(det)) break;
        double dd = -(p.L_qq * rd - p.L_dq * rq) / det;
        double dq = -(-p.L_qd * rd + p.L_dd * rq) / det;
        const double len = max_abs(dd, dq);
        if (len > cap) {
            dd *= cap / len;
            dq *= cap / len;
        }
        double a = 1.0;
        bool accepted = false;
        for (int ls = 0; ls < 40; ++ls, a *= 0.5) {
            const double nd = i_d + a * dd, nq = i_q + a * dq;
            const FluxPoint pn = map.eval(nd, nq);
            const double nrd = pn.psi_d - psi_d, nrq = pn.psi_q - psi_q;
            const double nrn = max_abs(nrd, nrq);
            if (nrn < (1.0 - 1e-4 * a) * rn || (a == 1.0 && nrn <= tol)) {
                i_d = nd;
                i_q = nq;
                p = pn;
                rd = nrd;
                rq = nrq;
                rn = nrn;
                accepted = true;
                break;
            }
        }
        if (!accepted) {
            // No decrease even for tiny steps: at rounding level already, or stuck.
            ok = rn <= 64 * tol;
            break;
        }
    }
    if (iterations) *iterations = it;
    return ok;
}

double step_cap(const FluxMap& map) {
    return 0.25 * std::max(map.i_d_max() - map.i_d_min(), map.i_q_max() - map.i_q_min());
}
// The regularised map as damped_newton sees it.
struct Regularised {
    const InverseFluxMap& inverse;
    FluxPoint eval(double i_d, double i_q) const { return inverse.forward_eval(i_d, i_q); }
};
}  // namespace

bool InverseFluxMap::invert(const FluxMap& map, double psi_d, double psi_q, double& i_d, double& i_q, double tol,
                            int* iterations) {
    return damped_newton(map, psi_d, psi_q, i_d, i_q, tol, iterations, step_cap(map));
}

bool InverseFluxMap::invert_regularised(double psi_d, double psi_q, double& i_d, double& i_q, double tol,
                                        int* iterations) const {
    return damped_newton(Regularised{*this}, psi_d, psi_q, i_d, i_q, tol, iterations, step_cap(forward_));
}

void InverseFluxMap::nearest_node(double psi_d, double psi_q, double& i_d, double& i_q) const {
    const std::ptrdiff_t n = nodes_.nearest(psi_d / psi_width_[0], psi_q / psi_width_[1]);
    if (n < 0) return;  // a NaN flux: keep the start, Newton fails on it
    i_d = node_i_d_[static_cast<std::size_t>(n)];
    i_q = node_i_q_[static_cast<std::size_t>(n)];
}

double InverseFluxMap::outside_legal(double i_d, double i_q) const {
    return std::max({legal_.i_d_min - i_d, i_d - legal_.i_d_max, legal_.i_q_min - i_q, i_q - legal_.i_q_max, 0.0});
}

InverseFluxPoint InverseFluxMap::search(double psi_d, double psi_q) const {
    // The regularised map is one-to-one (inverse_flux_map.hpp): the first converged search is it.
    constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
    SplineValue s[2];
    spline_.eval<2>(psi_d, psi_q, s);
    double i_d = s[0].f, i_q = s[1].f;
    bool ok = invert_regularised(psi_d, psi_q, i_d, i_q, flux_tol_);
    if (!ok) {
        nearest_node(psi_d, psi_q, i_d, i_q);
        ok = invert_regularised(psi_d, psi_q, i_d, i_q, flux_tol_);
    }
    if (!ok) return InverseFluxPoint{kNaN, kNaN, kNaN, kNaN, kNaN, kNaN};
    const FluxPoint p = forward_eval(i_d, i_q);
    const double det = p.L_dd * p.L_qq - p.L_dq * p.L_qd;
    return InverseFluxPoint{i_d, i_q, p.L_qq / det, -p.L_dq / det, -p.L_qd / det, p.L_dd / det};
}

InverseFluxMap::InverseFluxMap(const FluxMap& map, const InverseFluxMapOptions& options) : forward_(map) {
    const NodeRange b = snap_legal_box(
        map, options.legal.value_or(CurrentBox{map.i_d_min(), map.i_d_max(), map.i_q_min(), map.i_q_max()}));
    check_one_to_one(map, b, legal_);
    const PsiBox box = image_box(map, b, options.margin);
    PsiTable table = psi_grid(map, b, box, options);
    flux_tol_ = 1e-14 * std::max({std::abs(box.d_min), std::abs(box.d_max), std::abs(box.q_min), std::abs(box.q_max),
                                  box.width_d, box.width_q});
    step_tol_ = 1e-9 * std::max(map.i_d_max() - map.i_d_min(), map.i_q_max() - map.i_q_min());
    index_nodes(map.table(), b, box);
    invert_nodes(table);
    continue_unreachable(table);
    spline_ = BicubicSpline2D(table.psi_d, table.psi_q, {table.i_d.data(), table.i_q.data()});
    measure_errors(map, b);
}

// B: the legal box on the grid's nodes (legal_ set to it exactly), and those nodes.
InverseFluxMap::NodeRange InverseFluxMap::snap_legal_box(const FluxMap& map, const CurrentBox& legal) {
    const FluxMapTable& t = map.table();
    const int nd = static_cast<int>(t.i_d.size()), nq = static_cast<int>(t.i_q.size());
    const double tol_d = 1e-9 * (map.i_d_max() - map.i_d_min()), tol_q = 1e-9 * (map.i_q_max() - map.i_q_min());
    NodeRange b{nd, -1, nq, -1};
    for (int j = 0; j < nd; ++j)
        if (t.i_d[j] >= legal.i_d_min - tol_d && t.i_d[j] <= legal.i_d_max + tol_d) b.j0 = std::min(b.j0, j), b.j1 = j;
    for (int k = 0; k < nq; ++k)
        if (t.i_q[k] >= legal.i_q_min - tol_q && t.i_q[k] <= legal.i_q_max + tol_q) b.k0 = std::min(b.k0, k), b.k1 = k;
    if (b.j1 - b.j0 < 1 || b.k1 - b.k0 < 1)
        throw FluxMapError("InverseFluxMap: the legal box " + describe(legal) + " spans less than one grid cell");
    legal_ = CurrentBox{t.i_d[b.j0], t.i_d[b.j1], t.i_q[b.k0], t.i_q[b.k1]};
    return b;
}

// Currents must be a function of the flux linkages in B: the rule's defects (grid lines not
// monotone, L not a P-matrix at a node or a midpoint) must all lie beyond it.
void InverseFluxMap::check_one_to_one(const FluxMap& map, const NodeRange& b, const CurrentBox& legal) {
    for (const MapDefect& e : map_defects(map).list)
        if (e.d0 <= 2 * b.j1 && e.d1 >= 2 * b.j0 && e.q0 <= 2 * b.k1 && e.q1 >= 2 * b.k0)
            throw FluxMapError("InverseFluxMap: " + e.what + ", where the map is to be inverted (" + describe(legal) +
                               "): several currents give the same flux linkages there");
}

// The psi box: bounding box of the images of B's nodes and of its edges (the spline between
// edge nodes may bulge slightly beyond the node values), widened by the margin.
InverseFluxMap::PsiBox InverseFluxMap::image_box(const FluxMap& map, const NodeRange& b, double margin) {
    const FluxMapTable& t = map.table();
    double dmin = std::numeric_limits<double>::infinity(), dmax = -dmin, qmin = dmin, qmax = -dmin;
    auto take = [&](double id, double iq) {
        const FluxPoint p = map.eval(id, iq);
        dmin = std::min(dmin, p.psi_d);
        dmax = std::max(dmax, p.psi_d);
        qmin = std::min(qmin, p.psi_q);
        qmax = std::max(qmax, p.psi_q);
    };
    constexpr int kSub = 8;
    for (int k = b.k0; k <= b.k1; ++k)
        for (int j = b.j0; j <= b.j1; ++j) {
            take(t.i_d[j], t.i_q[k]);
            const bool edge_q = k == b.k0 || k == b.k1, edge_d = j == b.j0 || j == b.j1;
            for (int s = 1; s < kSub; ++s) {
                if (edge_q && j < b.j1) take(t.i_d[j] + (t.i_d[j + 1] - t.i_d[j]) * s / kSub, t.i_q[k]);
                if (edge_d && k < b.k1) take(t.i_d[j], t.i_q[k] + (t.i_q[k + 1] - t.i_q[k]) * s / kSub);
            }
        }
    const double wd = dmax - dmin, wq = qmax - qmin;
    if (!(wd > 0) || !(wq > 0) || !std::isfinite(wd) || !std::isfinite(wq))
        throw FluxMapError("InverseFluxMap: the flux map's image has no extent in psi_d or psi_q");
    return {dmin - margin * wd, dmax + margin * wd, qmin - margin * wq, qmax + margin * wq, wd, wq};
}

// The table's psi grid. Automatic resolution: psi spacing at most half the smallest flux step
// between adjacent grid nodes along that axis (the most saturated cell then still spans two psi
// cells), at least three psi cells per current cell, at most kMaxTableCells whatever the current
// grid: the table is only Newton's start, and its nodes are each a Newton inversion at
// construction, so a fine current grid (a FEM export of 511 x 511 points) must not size it.
InverseFluxMap::PsiTable InverseFluxMap::psi_grid(const FluxMap& map, const NodeRange& b, const PsiBox& box,
                                                  const InverseFluxMapOptions& options) {
    const FluxMapTable& t = map.table();
    const int nd = static_cast<int>(t.i_d.size());
    double step_d = std::numeric_limits<double>::infinity(), step_q = step_d;
    for (int k = b.k0; k <= b.k1; ++k)
        for (int j = b.j0; j <= b.j1; ++j) {
            const std::size_t i = static_cast<std::size_t>(k) * nd + j;
            if (j < b.j1) step_d = std::min(step_d, std::abs(t.psi_d[i + 1] - t.psi_d[i]));
            if (k < b.k1) step_q = std::min(step_q, std::abs(t.psi_q[i + nd] - t.psi_q[i]));
        }
    auto automatic = [](double width, double step, int n_current) {
        const double cells = step > 0 ? std::ceil(width / (0.5 * step)) : kMaxTableCells;
        const double lo = std::min(3.0 * (n_current - 1), kMaxTableCells);
        return static_cast<int>(std::min(std::max(cells, lo), kMaxTableCells)) + 1;
    };
    const int md = options.n_psi_d > 0 ? options.n_psi_d : automatic(box.d_max - box.d_min, step_d, b.j1 - b.j0 + 1);
    const int mq = options.n_psi_q > 0 ? options.n_psi_q : automatic(box.q_max - box.q_min, step_q, b.k1 - b.k0 + 1);
    if (md < 2 || mq < 2) throw FluxMapError("InverseFluxMap: the psi grid needs at least 2 x 2 nodes");
    PsiTable g;
    g.psi_d.resize(md);
    g.psi_q.resize(mq);
    for (int j = 0; j < md; ++j) g.psi_d[j] = box.d_min + (box.d_max - box.d_min) * j / (md - 1);
    for (int k = 0; k < mq; ++k) g.psi_q[k] = box.q_min + (box.q_max - box.q_min) * k / (mq - 1);
    g.psi_d.back() = box.d_max;
    g.psi_q.back() = box.q_max;
    g.i_d.assign(static_cast<std::size_t>(md) * mq, 0.0);
    g.i_q.assign(g.i_d.size(), 0.0);
    g.inverted.assign(g.i_d.size(), 0);
    return g;
}

// The start guesses' last resort: the node of B whose flux linkages are nearest (a k-d tree over
// them, in units of the image's extent).
void InverseFluxMap::index_nodes(const FluxMapTable& t, const NodeRange& b, const PsiBox& box) {
    const int nd = static_cast<int>(t.i_d.size());
    psi_width_[0] = box.width_d;
    psi_width_[1] = box.width_q;
    std::vector<double> x, y;
    for (int k = b.k0; k <= b.k1; ++k)
        for (int j = b.j0; j <= b.j1; ++j) {
            const std::size_t i = static_cast<std::size_t>(k) * nd + j;
            x.push_back(t.psi_d[i] / box.width_d);
            y.push_back(t.psi_q[i] / box.width_q);
            node_i_d_.push_back(t.i_d[j]);
            node_i_q_.push_back(t.i_q[k]);
        }
    nodes_ = NearestPoint2D(x, y);
}

// Each psi node inverted on the regularised map, from the previous node of the row
// (continuation), else the node below, else the nearest node of B.
void InverseFluxMap::invert_nodes(PsiTable& g) {
    const int md = static_cast<int>(g.psi_d.size()), mq = static_cast<int>(g.psi_q.size());
    for (int k = 0; k < mq; ++k)
        for (int j = 0; j < md; ++j) {
            const std::size_t idx = static_cast<std::size_t>(k) * md + j;
            double id = 0, iq = 0;
            bool ok = false;
            for (int attempt = 0; attempt < 3 && !ok; ++attempt) {
                if (attempt == 0 && j > 0) {
                    id = g.i_d[idx - 1];
                    iq = g.i_q[idx - 1];
                } else if (attempt <= 1 && k > 0) {
                    id = g.i_d[idx - md];
                    iq = g.i_q[idx - md];
                } else {
                    nearest_node(g.psi_d[j], g.psi_q[k], id, iq);
                }
                ok = invert_regularised(g.psi_d[j], g.psi_q[k], id, iq, flux_tol_);
            }
            if (!ok) {
                ++unreachable_nodes_;
                continue;
            }
            g.inverted[idx] = 1;
            const FluxPoint p = forward_eval(id, iq);
            max_residual_ = std::max(max_residual_, max_abs(p.psi_d - g.psi_d[j], p.psi_q - g.psi_q[k]));
            const double out = outside_legal(id, iq);
            if (out > 1e-9 * std::max(legal_.i_d_max - legal_.i_d_min, legal_.i_q_max - legal_.i_q_min)) {
                ++outside_nodes_;
                max_outside_ = std::max(max_outside_, out);
            }
            g.i_d[idx] = id;
            g.i_q[idx] = iq;
        }
    if (unreachable_nodes_ == md * mq)
        throw FluxMapError("InverseFluxMap: no node of the psi grid could be inverted: the map is not invertible");
}

// Unreachable nodes: first-order continuation of the inverse from an inverted (or already
// filled) neighbour, i = i_n + (d psi / d i)^-1 (psi - psi_n), sweeping outwards.
void InverseFluxMap::continue_unreachable(PsiTable& g) const {
    const int md = static_cast<int>(g.psi_d.size()), mq = static_cast<int>(g.psi_q.size());
    std::vector<std::size_t> front;
    for (std::size_t i = 0; i < g.inverted.size(); ++i)
        if (g.inverted[i]) front.push_back(i);
    while (!front.empty()) {
        std::vector<std::size_t> next;
        for (std::size_t from : front) {
            const int j = static_cast<int>(from % md), k = static_cast<int>(from / md);
            const int nb[4][2] = {{j - 1, k}, {j + 1, k}, {j, k - 1}, {j, k + 1}};
            for (const auto& n : nb) {
                if (n[0] < 0 || n[0] >= md || n[1] < 0 || n[1] >= mq) continue;
                const std::size_t to = static_cast<std::size_t>(n[1]) * md + n[0];
                if (g.inverted[to]) continue;
                const FluxPoint p = forward_eval(g.i_d[from], g.i_q[from]);
                const double det = p.L_dd * p.L_qq - p.L_dq * p.L_qd;
                const double rd = g.psi_d[n[0]] - p.psi_d, rq = g.psi_q[n[1]] - p.psi_q;
                g.i_d[to] = g.i_d[from] + (p.L_qq * rd - p.L_dq * rq) / det;
                g.i_q[to] = g.i_q[from] + (-p.L_qd * rd + p.L_dd * rq) / det;
                if (!std::isfinite(g.i_d[to]) || !std::isfinite(g.i_q[to])) {
                    g.i_d[to] = g.i_d[from];
                    g.i_q[to] = g.i_q[from];
                }
                g.inverted[to] = 1;
                next.push_back(to);
            }
        }
        front.swap(next);
    }
}

// The honest error: at each current-grid cell's centre in B, whose fluxes are the map's there.
void InverseFluxMap::measure_errors(const FluxMap& map, const NodeRange& b) {
    const FluxMapTable& t = map.table();
    for (int k = b.k0; k < b.k1; ++k)
        for (int j = b.j0; j < b.j1; ++j) {
            const double id = 0.5 * (t.i_d[j] + t.i_d[j + 1]), iq = 0.5 * (t.i_q[k] + t.i_q[k + 1]);
            const FluxPoint p = map.eval(id, iq);
            const InverseFluxPoint e = eval(p.psi_d, p.psi_q), g = table(p.psi_d, p.psi_q);
            const double err = max_abs(e.i_d - id, e.i_q - iq), gerr = max_abs(g.i_d - id, g.i_q - iq);
            max_error_ = std::isfinite(err) ? std::max(max_error_, err) : std::numeric_limits<double>::infinity();
            max_table_error_ =
                std::isfinite(gerr) ? std::max(max_table_error_, gerr) : std::numeric_limits<double>::infinity();
        }
}

}  // namespace ipmsm
