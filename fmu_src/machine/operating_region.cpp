// The flux-map acceptance rule; see operating_region.hpp.
#include "machine/operating_region.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "machine/map_file.hpp"

namespace ipmsm {
namespace {

std::string fmt(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.6g", v);
    return b;
}

// The doubled lattice of an axis: node j at 2 j, the midpoint of j and j + 1 at 2 j + 1.
double lattice(const std::vector<double>& axis, int a) {
    return a % 2 == 0 ? axis[a / 2] : 0.5 * (axis[a / 2] + axis[a / 2 + 1]);
}

// Grid nodes spanning [lo, hi] outwards: the last node <= lo and the first node >= hi (lattice).
void node_range(const std::vector<double>& axis, double lo, double hi, int& a0, int& a1) {
    const int n = static_cast<int>(axis.size());
    int j0 = 0, j1 = n - 1;
    for (int j = 0; j < n; ++j)
        if (axis[j] <= lo) j0 = j;
    for (int j = n - 1; j >= 0; --j)
        if (axis[j] >= hi) j1 = j;
    if (j1 < j0) j1 = j0;
    a0 = 2 * j0;
    a1 = 2 * j1;
}

struct LatticeBox {
    int d0, d1, q0, q1;
    bool meets(const MapDefect& e) const { return e.d0 <= d1 && e.d1 >= d0 && e.q0 <= q1 && e.q1 >= q0; }
    double area(const FluxMapTable& t) const {
        return (lattice(t.i_d, d1) - lattice(t.i_d, d0)) * (lattice(t.i_q, q1) - lattice(t.i_q, q0));
    }
};

int distance(const LatticeBox& b, const MapDefect& e) {
    const int dd = std::max({b.d0 - e.d1, e.d0 - b.d1, 0}), dq = std::max({b.q0 - e.q1, e.q0 - b.q1, 0});
    return std::max(dd, dq);
}

CurrentBox currents(const FluxMapTable& t, const LatticeBox& b) {
    return {lattice(t.i_d, b.d0), lattice(t.i_d, b.d1), lattice(t.i_q, b.q0), lattice(t.i_q, b.q1)};
}

std::string region_words(const OperatingRegion& r) {
    return "the I_max = " + fmt(r.I_max) + " A circle" + (r.magnet ? ", i_d <= 0 (a machine with a magnet)" : "") +
           ", widened by " + fmt(100 * kOperatingMargin) + " % of I_max: " + describe(r.required);
}

}  // namespace

std::string describe(const CurrentBox& b) {
    return "i_d in [" + fmt(b.i_d_min) + ", " + fmt(b.i_d_max) + "] A, i_q in [" + fmt(b.i_q_min) + ", " +
           fmt(b.i_q_max) + "] A";
}

OperatingRegion operating_region(const FluxMap& map, double I_max) {
    const FluxMapTable& t = map.table();
    double psi_d_largest = 0;
    for (double p : t.psi_d) psi_d_largest = std::max(psi_d_largest, std::abs(p));
    OperatingRegion r;
    r.I_max = I_max;
    r.magnet = map.psi_m() >= kMagnetFraction * psi_d_largest && map.psi_m() > 0;
    const double m = kOperatingMargin * I_max;
    auto cut = [](double lo, double hi, double a, double b, double& x0, double& x1) {
        x0 = std::min(std::max(lo, a), b);
        x1 = std::max(std::min(hi, b), x0);
    };
    cut(-I_max - m, (r.magnet ? 0.0 : I_max) + m, map.i_d_min(), map.i_d_max(), r.required.i_d_min, r.required.i_d_max);
    cut(-I_max - m, I_max + m, map.i_q_min(), map.i_q_max(), r.required.i_q_min, r.required.i_q_max);
    return r;
}

MapDefects map_defects(const FluxMap& map, std::size_t max_defects) {
    const FluxMapTable& t = map.table();
    const int nd = static_cast<int>(t.i_d.size()), nq = static_cast<int>(t.i_q.size());
    MapDefects out;
    auto add = [&](std::string what, int d0, int d1, int q0, int q1) {
        ++out.count;
        if (out.list.size() < max_defects)
            out.list.push_back({std::move(what), std::max(d0, 0), std::min(d1, 2 * nd - 2), std::max(q0, 0),
                                std::min(q1, 2 * nq - 2)});
    };
    // The data: strictly positive incremental self-inductances between adjacent nodes.
    for (int k = 0; k < nq; ++k)
        for (int j = 0; j + 1 < nd; ++j) {
            const std::size_t a = static_cast<std::size_t>(k) * nd + j, b = a + 1;
            if (!(t.psi_d[b] > t.psi_d[a]))
                add("psi_d not strictly increasing in i_d along i_q = " + fmt(t.i_q[k]) +
                        " A: psi_d = " + fmt(t.psi_d[a]) + " Wb at i_d = " + fmt(t.i_d[j]) +
                        " A, psi_d = " + fmt(t.psi_d[b]) + " Wb at i_d = " + fmt(t.i_d[j + 1]) + " A",
                    2 * j, 2 * j + 2, 2 * k, 2 * k);
        }
    for (int j = 0; j < nd; ++j)
        for (int k = 0; k + 1 < nq; ++k) {
            const std::size_t a = static_cast<std::size_t>(k) * nd + j, b = a + nd;
            if (!(t.psi_q[b] > t.psi_q[a]))
                add("psi_q not strictly increasing in i_q along i_d = " + fmt(t.i_d[j]) +
                        " A: psi_q = " + fmt(t.psi_q[a]) + " Wb at i_q = " + fmt(t.i_q[k]) +
                        " A, psi_q = " + fmt(t.psi_q[b]) + " Wb at i_q = " + fmt(t.i_q[k + 1]) + " A",
                    2 * j, 2 * j + 2, 2 * k, 2 * k + 2);
        }
    // The spline: L a P-matrix at every node, edge midpoint and cell centre; a failure there
    // spans its lattice neighbours (the spline between samples is not checked).
    for (int b = 0; b < 2 * nq - 1; ++b)
        for (int a = 0; a < 2 * nd - 1; ++a) {
            const double id = lattice(t.i_d, a), iq = lattice(t.i_q, b);
            const FluxPoint p = map.eval(id, iq);
            const double det = p.L_dd * p.L_qq - p.L_dq * p.L_qd;
            if (p.L_dd > 0 && p.L_qq > 0 && det > kFoldRelative * std::abs(p.L_dd * p.L_qq)) continue;
            char w[320];
            std::snprintf(w, sizeof w,
                          "the flux map folds at i_d = %.6g A, i_q = %.6g A: the incremental inductances "
                          "L_dd = %.4g, L_dq = %.4g, L_qd = %.4g, L_qq = %.4g H (determinant %.3g H^2); L_dd, "
                          "L_qq and the determinant must be > 0",
                          id, iq, p.L_dd, p.L_dq, p.L_qd, p.L_qq, det);
            add(w, a - 1, a + 1, b - 1, b + 1);
        }
    return out;
}

MapAcceptance accept_flux_map(const FluxMap& map, double I_max, const std::string& map_name) {
    const FluxMapTable& t = map.table();
    const int nd = static_cast<int>(t.i_d.size()), nq = static_cast<int>(t.i_q.size());
    MapAcceptance acc;
    acc.region = operating_region(map, I_max);
    const MapDefects defects = map_defects(map, std::numeric_limits<std::size_t>::max());
    acc.defects = defects.count;
    LatticeBox required{};
    node_range(t.i_d, acc.region.required.i_d_min, acc.region.required.i_d_max, required.d0, required.d1);
    node_range(t.i_q, acc.region.required.i_q_min, acc.region.required.i_q_max, required.q0, required.q1);
    const std::string name = "flux map '" + quoted_excerpt(map_name) + "'";
    for (const MapDefect& e : defects.list)
        if (required.meets(e))
            throw FluxMapError(name + ": " + e.what + ", inside the drive's operating region (" +
                               region_words(acc.region) + "; " + std::to_string(defects.count) +
                               " such place(s) on the map in all): the currents there would not be a function of "
                               "the flux linkages. Repair the map (python -m scenarios map repair '" +
                               quoted_excerpt(map_name) + "' --out FIXED.csv) or lower I_max");

    // The legal box: from the whole grid, each defect (nearest first) cut off on the side that
    // keeps the largest box; every defect lies outside the required box, so one side can.
    LatticeBox legal{0, 2 * nd - 2, 0, 2 * nq - 2};
    std::vector<const MapDefect*> order;
    for (const MapDefect& e : defects.list) order.push_back(&e);
    std::stable_sort(order.begin(), order.end(), [&](const MapDefect* x, const MapDefect* y) {
        return distance(required, *x) < distance(required, *y);
    });
    for (const MapDefect* e : order) {
        if (!legal.meets(*e)) continue;
        LatticeBox best{}, c = legal;
        double best_area = -1;
        auto consider = [&](const LatticeBox& b) {
            const bool ok = b.d0 <= required.d0 && b.d1 >= required.d1 && b.q0 <= required.q0 && b.q1 >= required.q1;
            if (ok && b.area(t) > best_area) {
                best_area = b.area(t);
                best = b;
            }
        };
        if (e->d0 >= 1) {
            c.d1 = std::min(legal.d1, (e->d0 - 1) / 2 * 2);  // the last node before the defect
            consider(c);
        }
        if ((e->d1 + 2) / 2 * 2 <= 2 * nd - 2) {
            c = legal;
            c.d0 = std::max(legal.d0, (e->d1 + 2) / 2 * 2);  // the first node after it
            consider(c);
        }
        if (e->q0 >= 1) {
            c = legal;
            c.q1 = std::min(legal.q1, (e->q0 - 1) / 2 * 2);
            consider(c);
        }
        if ((e->q1 + 2) / 2 * 2 <= 2 * nq - 2) {
            c = legal;
            c.q0 = std::max(legal.q0, (e->q1 + 2) / 2 * 2);
            consider(c);
        }
        legal = best_area >= 0 ? best : required;  // (a defect outside the required box always leaves one)
    }
    acc.legal = currents(t, legal);
    if (defects.count == 0) return acc;

    std::string w = name + ": not legal at " + std::to_string(defects.count) +
                    " place(s), all outside the drive's operating region (" + region_words(acc.region) +
                    "), so accepted: ";
    constexpr std::size_t kNamed = 3;
    for (std::size_t i = 0; i < std::min(kNamed, defects.list.size()); ++i) w += (i ? "; " : "") + defects.list[i].what;
    if (defects.count > kNamed) w += "; and " + std::to_string(defects.count - kNamed) + " more";
    w += ". The map is used on " + describe(acc.legal) +
         "; beyond, the plant continues it with positive-definite incremental inductances (docs/maps.md). "
         "python -m scenarios map check shows every place";
    acc.warning = w;
    return acc;
}

}  // namespace ipmsm
