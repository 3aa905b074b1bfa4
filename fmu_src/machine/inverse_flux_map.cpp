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

}  // namespace

bool InverseFluxMap::invert(const FluxMap& map, double psi_d, double psi_q, double& i_d, double& i_q, double tol,
                            int* iterations) {
    // Damped Newton on r(i) = psi(i) - psi*, backtracking on the max-norm of r. The step size
    // is also capped at a quarter of the grid's extent so that a poor start cannot throw the
    // iterate far into the extrapolated region in one step.
    const double cap = 0.25 * std::max(map.i_d_max() - map.i_d_min(), map.i_q_max() - map.i_q_min());
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

void InverseFluxMap::nearest_node(double psi_d, double psi_q, double& i_d, double& i_q) const {
    const FluxMapTable& t = forward_.table();
    const std::size_t nd = t.i_d.size(), nq = t.i_q.size();
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < nq; ++k)
        for (std::size_t j = 0; j < nd; ++j) {
            const std::size_t i = k * nd + j;
            const double e = std::hypot((t.psi_d[i] - psi_d) / psi_width_[0], (t.psi_q[i] - psi_q) / psi_width_[1]);
            if (e < best) {
                best = e;
                i_d = t.i_d[j];
                i_q = t.i_q[k];
            }
        }
}

double InverseFluxMap::outside_grid(double i_d, double i_q) const {
    return std::max(
        {forward_.i_d_min() - i_d, i_d - forward_.i_d_max(), forward_.i_q_min() - i_q, i_q - forward_.i_q_max(), 0.0});
}

InverseFluxPoint InverseFluxMap::search(double psi_d, double psi_q, const double* fast) const {
    // Candidates: the fast Newton's solution (if it converged), damped Newton from the table's
    // guess and from the grid node with the nearest fluxes. Beyond the grid a map's linear
    // continuation may fold, so the same fluxes can have several preimages: the one nearest
    // the grid is the machine's (it is reached continuously from inside).
    constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
    double best[2] = {kNaN, kNaN}, best_out = std::numeric_limits<double>::infinity();
    auto consider = [&](double i_d, double i_q) {
        const double out = outside_grid(i_d, i_q);
        if (out < best_out) {
            best_out = out;
            best[0] = i_d;
            best[1] = i_q;
        }
    };
    if (fast != nullptr) consider(fast[0], fast[1]);
    if (best_out > 0) {
        SplineValue s[2];
        spline_.eval<2>(psi_d, psi_q, s);
        double i_d = s[0].f, i_q = s[1].f;
        if (invert(forward_, psi_d, psi_q, i_d, i_q, flux_tol_)) consider(i_d, i_q);
    }
    if (best_out > 0) {
        double i_d = 0, i_q = 0;
        nearest_node(psi_d, psi_q, i_d, i_q);
        if (invert(forward_, psi_d, psi_q, i_d, i_q, flux_tol_)) consider(i_d, i_q);
    }
    if (!std::isfinite(best_out)) return InverseFluxPoint{kNaN, kNaN, kNaN, kNaN, kNaN, kNaN};
    const FluxPoint p = forward_.eval(best[0], best[1]);
    const double det = p.L_dd * p.L_qq - p.L_dq * p.L_qd;
    return InverseFluxPoint{best[0], best[1], p.L_qq / det, -p.L_dq / det, -p.L_qd / det, p.L_dd / det};
}

InverseFluxMap::InverseFluxMap(const FluxMap& map, const InverseFluxMapOptions& options) : forward_(map) {
    const FluxMapTable& t = map.table();
    const int nd = static_cast<int>(t.i_d.size()), nq = static_cast<int>(t.i_q.size());

    // Currents must be a function of the flux linkages on the grid: the incremental inductance
    // matrix d psi / d i nonsingular with a positive determinant (the contract's monotone grid
    // lines do not imply it for a non-reciprocal map). Checked at the nodes and at the cells'
    // and edges' midpoints; refused with where it fails, since the inverse would be ambiguous.
    for (int k = 0; k < 2 * nq - 1; ++k)
        for (int j = 0; j < 2 * nd - 1; ++j) {
            const double id = j % 2 == 0 ? t.i_d[j / 2] : 0.5 * (t.i_d[j / 2] + t.i_d[j / 2 + 1]);
            const double iq = k % 2 == 0 ? t.i_q[k / 2] : 0.5 * (t.i_q[k / 2] + t.i_q[k / 2 + 1]);
            const FluxPoint p = map.eval(id, iq);
            const double det = p.L_dd * p.L_qq - p.L_dq * p.L_qd;
            if (!(det > 1e-12 * std::abs(p.L_dd * p.L_qq))) {
                char b[320];
                std::snprintf(b, sizeof b,
                              "InverseFluxMap: the flux map folds at i_d = %.6g A, i_q = %.6g A: the incremental "
                              "inductances L_dd = %.4g, L_dq = %.4g, L_qd = %.4g, L_qq = %.4g H have a determinant "
                              "%.3g H^2 <= 0, so several currents give the same flux linkages there",
                              id, iq, p.L_dd, p.L_dq, p.L_qd, p.L_qq, det);
                throw FluxMapError(b);
            }
        }

    // The psi box: bounding box of the images of the grid nodes and of the grid's edges (the
    // spline between edge nodes may bulge slightly beyond the node values).
    double dmin = std::numeric_limits<double>::infinity(), dmax = -dmin, qmin = dmin, qmax = -dmin;
    auto take = [&](double id, double iq) {
        const FluxPoint p = map.eval(id, iq);
        dmin = std::min(dmin, p.psi_d);
        dmax = std::max(dmax, p.psi_d);
        qmin = std::min(qmin, p.psi_q);
        qmax = std::max(qmax, p.psi_q);
    };
    constexpr int kSub = 8;
    for (int k = 0; k < nq; ++k)
        for (int j = 0; j < nd; ++j) {
            take(t.i_d[j], t.i_q[k]);
            const bool edge_q = k == 0 || k == nq - 1, edge_d = j == 0 || j == nd - 1;
            for (int s = 1; s < kSub; ++s) {
                if (edge_q && j + 1 < nd) take(t.i_d[j] + (t.i_d[j + 1] - t.i_d[j]) * s / kSub, t.i_q[k]);
                if (edge_d && k + 1 < nq) take(t.i_d[j], t.i_q[k] + (t.i_q[k + 1] - t.i_q[k]) * s / kSub);
            }
        }
    const double wd = dmax - dmin, wq = qmax - qmin;
    if (!(wd > 0) || !(wq > 0) || !std::isfinite(wd) || !std::isfinite(wq))
        throw FluxMapError("InverseFluxMap: the flux map's image has no extent in psi_d or psi_q");
    dmin -= options.margin * wd;
    dmax += options.margin * wd;
    qmin -= options.margin * wq;
    qmax += options.margin * wq;
    // Automatic resolution: psi spacing at most half the smallest flux step between adjacent
    // grid nodes along that axis (the most saturated cell then still spans two psi cells), at
    // least three psi cells per current cell, at most kMaxTableCells (or one per current cell).
    double step_d = std::numeric_limits<double>::infinity(), step_q = step_d;
    for (int k = 0; k < nq; ++k)
        for (int j = 0; j < nd; ++j) {
            const std::size_t i = static_cast<std::size_t>(k) * nd + j;
            if (j + 1 < nd) step_d = std::min(step_d, std::abs(t.psi_d[i + 1] - t.psi_d[i]));
            if (k + 1 < nq) step_q = std::min(step_q, std::abs(t.psi_q[i + nd] - t.psi_q[i]));
        }
    auto automatic = [](double width, double step, int n_current) {
        const double cells = step > 0 ? std::ceil(width / (0.5 * step)) : kMaxTableCells;
        const double lo = 3.0 * (n_current - 1), hi = std::max(kMaxTableCells, n_current - 1.0);
        return static_cast<int>(std::min(std::max(cells, lo), hi)) + 1;
    };
    const int md = options.n_psi_d > 0 ? options.n_psi_d : automatic(dmax - dmin, step_d, nd);
    const int mq = options.n_psi_q > 0 ? options.n_psi_q : automatic(qmax - qmin, step_q, nq);
    if (md < 2 || mq < 2) throw FluxMapError("InverseFluxMap: the psi grid needs at least 2 x 2 nodes");
    std::vector<double> pd(md), pq(mq);
    for (int j = 0; j < md; ++j) pd[j] = dmin + (dmax - dmin) * j / (md - 1);
    for (int k = 0; k < mq; ++k) pq[k] = qmin + (qmax - qmin) * k / (mq - 1);
    pd.back() = dmax;
    pq.back() = qmax;

    const double tol = 1e-14 * std::max({std::abs(dmin), std::abs(dmax), std::abs(qmin), std::abs(qmax), wd, wq});
    flux_tol_ = tol;
    step_tol_ = 1e-9 * std::max(map.i_d_max() - map.i_d_min(), map.i_q_max() - map.i_q_min());
    std::vector<double> cd(static_cast<std::size_t>(md) * mq), cq(cd.size());
    std::vector<char> inverted(cd.size(), 0);

    // Start guesses: the previous node of the row (continuation), else the node below, else
    // the current-grid node whose flux linkages are nearest.
    psi_width_[0] = wd;
    psi_width_[1] = wq;
    const double gd0 = map.i_d_min(), gd1 = map.i_d_max(), gq0 = map.i_q_min(), gq1 = map.i_q_max();
    for (int k = 0; k < mq; ++k)
        for (int j = 0; j < md; ++j) {
            const std::size_t idx = static_cast<std::size_t>(k) * md + j;
            double id = 0, iq = 0;
            bool ok = false;
            for (int attempt = 0; attempt < 3 && !ok; ++attempt) {
                if (attempt == 0 && j > 0) {
                    id = cd[idx - 1];
                    iq = cq[idx - 1];
                } else if (attempt <= 1 && k > 0) {
                    id = cd[idx - md];
                    iq = cq[idx - md];
                } else {
                    nearest_node(pd[j], pq[k], id, iq);
                }
                ok = invert(map, pd[j], pq[k], id, iq, tol);
            }
            if (!ok) {
                ++unreachable_nodes_;
                continue;
            }
            inverted[idx] = 1;
            const FluxPoint p = map.eval(id, iq);
            max_residual_ = std::max(max_residual_, max_abs(p.psi_d - pd[j], p.psi_q - pq[k]));
            const double out = std::max({gd0 - id, id - gd1, gq0 - iq, iq - gq1});
            if (out > 1e-9 * std::max(gd1 - gd0, gq1 - gq0)) {
                ++outside_nodes_;
                max_outside_ = std::max(max_outside_, out);
            }
            cd[idx] = id;
            cq[idx] = iq;
        }
    if (unreachable_nodes_ == md * mq)
        throw FluxMapError("InverseFluxMap: no node of the psi grid could be inverted: the map is not invertible");
    // Unreachable nodes: first-order continuation of the inverse from an inverted (or already
    // filled) neighbour, i = i_n + (d psi / d i)^-1 (psi - psi_n), sweeping outwards.
    std::vector<std::size_t> front;
    for (std::size_t i = 0; i < inverted.size(); ++i)
        if (inverted[i]) front.push_back(i);
    while (!front.empty()) {
        std::vector<std::size_t> next;
        for (std::size_t from : front) {
            const int j = static_cast<int>(from % md), k = static_cast<int>(from / md);
            const int nb[4][2] = {{j - 1, k}, {j + 1, k}, {j, k - 1}, {j, k + 1}};
            for (const auto& n : nb) {
                if (n[0] < 0 || n[0] >= md || n[1] < 0 || n[1] >= mq) continue;
                const std::size_t to = static_cast<std::size_t>(n[1]) * md + n[0];
                if (inverted[to]) continue;
                const FluxPoint p = map.eval(cd[from], cq[from]);
                const double det = p.L_dd * p.L_qq - p.L_dq * p.L_qd;
                const double rd = pd[n[0]] - p.psi_d, rq = pq[n[1]] - p.psi_q;
                cd[to] = cd[from] + (p.L_qq * rd - p.L_dq * rq) / det;
                cq[to] = cq[from] + (-p.L_qd * rd + p.L_dd * rq) / det;
                if (!std::isfinite(cd[to]) || !std::isfinite(cq[to])) {
                    cd[to] = cd[from];
                    cq[to] = cq[from];
                }
                inverted[to] = 1;
                next.push_back(to);
            }
        }
        front.swap(next);
    }
    spline_ = BicubicSpline2D(pd, pq, {cd.data(), cq.data()});

    // The honest error: at each current-grid cell's centre, whose fluxes are the map's there.
    for (int k = 0; k + 1 < nq; ++k)
        for (int j = 0; j + 1 < nd; ++j) {
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
