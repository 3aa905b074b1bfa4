// The flux-map acceptance rule (machine/operating_region.hpp) and the inverse map's nearest-node
// index (machine/nearest_point.hpp): tests that fail on the old behaviour (every non-monotone or
// folding map refused; a scan over every node).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "flux_map_generators.hpp"
#include "machine/flux_map.hpp"
#include "machine/inverse_flux_map.hpp"
#include "machine/nearest_point.hpp"
#include "machine/operating_region.hpp"

using namespace ipmsm;

namespace {

// A linear machine on [-300, 300] A (25 A steps), psi_m = psi_m; one grid segment made to fall:
// psi_d at (i_d_bad + 25, i_q_bad) set below psi_d at (i_d_bad, i_q_bad).
FluxMapTable with_falling_segment(double psi_m, double i_d_bad, double i_q_bad) {
    FluxMapTable t = linear_flux_map(2e-4, 6e-4, psi_m, 300, 25);
    const std::size_t nd = t.i_d.size();
    for (std::size_t k = 0; k < t.i_q.size(); ++k)
        for (std::size_t j = 0; j + 1 < nd; ++j)
            if (t.i_d[j] == i_d_bad && t.i_q[k] == i_q_bad) t.psi_d[k * nd + j + 1] = t.psi_d[k * nd + j] - 1e-3;
    return t;
}

// Saturating q axis (tanh, I_s = 300 A) and a cross-coupling bump of width 40 A at (30, -600) A
// whose incremental inductances fold there (det L < 0) while every grid line stays monotone:
// "a map whose incremental inductances fold only at its far corner" of a 500 A machine.
FluxMapTable far_corner_fold() {
    const double L_d = 2e-4, L_q = 6e-4, I_s = 300, s = 40, a = 5e-5, b = 3e-4, c_d = 30, c_q = -600;
    FluxMapTable t;
    for (double x = -570; x <= 630 + 1e-9; x += 20) t.i_d.push_back(x);
    for (double y = -700; y <= 700 + 1e-9; y += 25) t.i_q.push_back(y);
    for (double iq : t.i_q)
        for (double id : t.i_d) {
            const double x = id - c_d, y = iq - c_q, bump = std::exp(-(x * x + y * y) / (2 * s * s));
            t.psi_d.push_back(0.08 + L_d * id + b * y * bump);
            t.psi_q.push_back(L_q * I_s * std::tanh(iq / I_s) + a * x * bump);
        }
    return t;
}

}  // namespace

TEST(OperatingRegion, MagnetHalfPlaneAndMargin) {
    const FluxMap pm(linear_flux_map(2e-4, 6e-4, 0.08, 300, 25)), syrm(linear_flux_map(2e-4, 6e-4, 0.0, 300, 25));
    const OperatingRegion a = operating_region(pm, 200), b = operating_region(syrm, 200);
    EXPECT_TRUE(a.magnet);
    EXPECT_FALSE(b.magnet);
    EXPECT_DOUBLE_EQ(a.required.i_d_min, -220);
    EXPECT_DOUBLE_EQ(a.required.i_d_max, 20);  // i_d <= 0 with a magnet, plus 10 % of I_max
    EXPECT_DOUBLE_EQ(b.required.i_d_max, 220);
    EXPECT_DOUBLE_EQ(a.required.i_q_max, 220);
    EXPECT_DOUBLE_EQ(operating_region(pm, 500).required.i_q_max, 300);  // cut to the grid
}

TEST(MapAcceptance, DefectBeyondTheRegionIsAcceptedWithOneWarningNamingIt) {
    const FluxMap m(with_falling_segment(0.08, 150, 50));
    const MapAcceptance acc = accept_flux_map(m, 200, "bent.csv");
    EXPECT_EQ(acc.defects, map_defects(m).count);
    EXPECT_GE(acc.defects, 1u);
    EXPECT_NE(acc.warning.find("psi_d not strictly increasing in i_d along i_q = 50 A"), std::string::npos)
        << acc.warning;
    EXPECT_NE(acc.warning.find("bent.csv"), std::string::npos);
    EXPECT_LT(acc.warning.size(), 2000u);
    // The legal box keeps the operating region and leaves the defect out.
    EXPECT_LE(acc.legal.i_d_min, -220);
    EXPECT_GE(acc.legal.i_d_max, 20);
    EXPECT_FALSE(acc.legal.contains(150, 50) && acc.legal.contains(175, 50));
    // The plant's inverse on that box is exact inside and unique everywhere.
    InverseFluxMapOptions o;
    o.legal = acc.legal;
    const InverseFluxMap inv(m, o);
    EXPECT_LT(inv.max_error_A(), 1e-9);
    for (double pd = -0.3; pd <= 0.3; pd += 0.01)
        for (double pq = -0.4; pq <= 0.4; pq += 0.01) {
            const InverseFluxPoint q = inv.eval(pd, pq);
            ASSERT_TRUE(std::isfinite(q.i_d)) << pd << ", " << pq;
            const FluxPoint p = inv.forward_eval(q.i_d, q.i_q);
            ASSERT_NEAR(p.psi_d, pd, 1e-12);
            ASSERT_NEAR(p.psi_q, pq, 1e-12);
        }
    // Without a legal box (the whole grid) the inverse refuses the map, as before.
    EXPECT_THROW(InverseFluxMap{m}, FluxMapError);
}

TEST(MapAcceptance, DefectInsideTheRegionIsRefusedSayingWhereAndWhatToDo) {
    // The same defect, on a magnet-free machine: the whole I_max disc is operated.
    try {
        accept_flux_map(FluxMap(with_falling_segment(0.0, 150, 50)), 200, "syrm.csv");
        FAIL() << "no exception";
    } catch (const FluxMapError& e) {
        const std::string w = e.what();
        EXPECT_NE(w.find("syrm.csv"), std::string::npos) << w;
        EXPECT_NE(w.find("psi_d not strictly increasing in i_d along i_q = 50 A"), std::string::npos) << w;
        EXPECT_NE(w.find("i_d = 150 A"), std::string::npos) << w;
        EXPECT_NE(w.find("inside the drive's operating region"), std::string::npos) << w;
        EXPECT_NE(w.find("python -m scenarios map repair"), std::string::npos) << w;
    }
    // A PM machine with the defect at i_d < 0 within I_max.
    EXPECT_THROW(accept_flux_map(FluxMap(with_falling_segment(0.08, -100, 0)), 200, "pm.csv"), FluxMapError);
    // ... and with a larger I_max the first defect is inside too.
    EXPECT_THROW(accept_flux_map(FluxMap(with_falling_segment(0.08, 150, 50)), 200 / 0.1, "pm.csv"), FluxMapError);
}

TEST(MapAcceptance, FarCornerFoldOfA500AMachineLoads) {
    const FluxMap m(far_corner_fold());
    const MapDefects d = map_defects(m);
    ASSERT_GT(d.count, 0u);  // the test can fail: the map does fold
    for (const MapDefect& e : d.list) EXPECT_NE(e.what.find("folds at"), std::string::npos) << e.what;
    const MapAcceptance acc = accept_flux_map(m, 500, "corner.csv");
    EXPECT_NE(acc.warning.find("folds at i_d = "), std::string::npos) << acc.warning;
    EXPECT_FALSE(acc.legal.contains(30, -600));
    EXPECT_TRUE(acc.legal.contains(-500, -550) && acc.legal.contains(50, 550));
    EXPECT_THROW(InverseFluxMap{m}, FluxMapError);  // the old rule: refused at initialisation
    InverseFluxMapOptions o;
    o.legal = acc.legal;
    const InverseFluxMap inv(m, o);
    EXPECT_LT(inv.max_error_A(), 1e-9);
    // Near and beyond the fold: one current per flux linkage, found exactly.
    for (double id = -100; id <= 150; id += 7)
        for (double iq = -700; iq <= -450; iq += 6) {
            const FluxPoint p = inv.forward_eval(id, iq);
            const InverseFluxPoint q = inv.eval(p.psi_d, p.psi_q);
            ASSERT_NEAR(q.i_d, id, 1e-7) << id << ", " << iq;
            ASSERT_NEAR(q.i_q, iq, 1e-7) << id << ", " << iq;
        }
    // With I_max reaching the fold it is refused, naming where.
    try {
        accept_flux_map(m, 580, "corner.csv");
        FAIL() << "no exception";
    } catch (const FluxMapError& e) {
        EXPECT_NE(std::string(e.what()).find("folds at i_d = "), std::string::npos) << e.what();
    }
}

// The nearest node: the k-d tree agrees with a scan and visits O(log N) points for queries
// within the points' extent, O(sqrt N) for queries far beyond a straight edge (all the edge's
// points are then nearly equally near); the scan (the old InverseFluxMap::nearest_node: 14 min of
// map show on a 125 751-node map) visits N.
TEST(NearestPoint2D, AgreesWithTheScanAndVisitsFewPoints) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> u(-1, 1);
    double near_visits[2] = {0, 0}, far_visits[2] = {0, 0};
    const std::size_t sides[2] = {50, 500};
    for (int s = 0; s < 2; ++s) {
        const std::size_t m = sides[s], n = m * m;
        std::vector<double> x(n), y(n);
        for (std::size_t i = 0; i < n; ++i) {  // a saturated map's image: a warped grid
            const double a = -1 + 2.0 * (i % m) / (m - 1), b = -1 + 2.0 * (i / m) / (m - 1);
            x[i] = std::tanh(2 * a) + 0.2 * b;
            y[i] = b * (1 + 0.5 * a);
        }
        const NearestPoint2D tree(x, y);
        const int queries = 2000;
        for (int q = 0; q < queries; ++q) {
            const bool far = q % 2 == 1;
            const double qx = (far ? 3 : 1.1) * u(rng), qy = (far ? 3 : 1.1) * u(rng);
            std::size_t visits = 0;
            const std::ptrdiff_t k = tree.nearest(qx, qy, &visits);
            ASSERT_GE(k, 0);
            (far ? far_visits : near_visits)[s] += 2.0 * static_cast<double>(visits) / queries;
            if (q % 10 < 2) {
                double best = INFINITY;
                for (std::size_t i = 0; i < n; ++i) best = std::min(best, std::hypot(x[i] - qx, y[i] - qy));
                ASSERT_EQ(std::hypot(x[k] - qx, y[k] - qy), best);
            }
        }
    }
    std::printf("  k-d tree: mean visits near %.1f at N = 2500, %.1f at N = 250000; far %.1f, %.1f\n", near_visits[0],
                near_visits[1], far_visits[0], far_visits[1]);
    EXPECT_LT(near_visits[1], 5 * near_visits[0]);  // a scan: 100 times
    EXPECT_LT(far_visits[1], 15 * far_visits[0]);
    EXPECT_LT(far_visits[1], 0.01 * 250000);
    EXPECT_EQ(NearestPoint2D().nearest(0, 0), -1);
}

// Far outside the table on a large map, eval() reaches the nearest-node search (k-d tree: its
// visits do not grow with the nodes, NearestPoint2D above counts them; bench_flux_map times it).
// Whatever the node count, the currents it returns are the regularised map's exact inverse there.
TEST(InverseFluxMap, FarOutsideTheTableIsExactAtAnyNodeCount) {
    for (const int nodes : {60, 240}) {
        const FluxMap m(saturating_flux_map(2e-4, 6e-4, 0.08, 200, 0.1, 300, 500, nodes));
        const InverseFluxMap inv(m);
        int far = 0;
        for (double pd = -3; pd <= 3; pd += 0.25)
            for (double pq = -3; pq <= 3; pq += 0.25) {
                const InverseFluxPoint e = inv.eval(pd, pq);
                ASSERT_TRUE(std::isfinite(e.i_d) && std::isfinite(e.i_q)) << nodes << ": " << pd << ", " << pq;
                const FluxPoint p = inv.forward_eval(e.i_d, e.i_q);
                EXPECT_NEAR(p.psi_d, pd, 1e-9 * 3) << nodes << ": " << pd << ", " << pq;
                EXPECT_NEAR(p.psi_q, pq, 1e-9 * 3) << nodes << ": " << pd << ", " << pq;
                far += pd < inv.psi_d_min() || pd > inv.psi_d_max() || pq < inv.psi_q_min() || pq > inv.psi_q_max();
            }
        EXPECT_GT(far, 400) << nodes;  // most of the square lies beyond the table
    }
}

// The continuation's inductances are the derivatives of its fluxes (Newton, CVODE's Jacobian),
// beyond edges and corners, and its fluxes are continuous across B's edges.
TEST(InverseFluxMap, ContinuationDerivativesMatchFiniteDifferences) {
    const FluxMap m(saturating_flux_map(2e-4, 6e-4, 0.08, 150, 0.15, 300, 500, 21));
    InverseFluxMapOptions o;
    o.legal = CurrentBox{-400, 300, -350, 450};
    const InverseFluxMap inv(m, o);
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> u(-900, 900);
    const double h = 1e-3;
    int beyond = 0;
    for (int s = 0; s < 2000; ++s) {
        const double id = u(rng), iq = u(rng);
        if (std::abs(id - inv.legal().i_d_min) < 2 * h || std::abs(id - inv.legal().i_d_max) < 2 * h ||
            std::abs(iq - inv.legal().i_q_min) < 2 * h || std::abs(iq - inv.legal().i_q_max) < 2 * h)
            continue;  // a kink of the Jacobian on B's edges
        beyond += !inv.legal().contains(id, iq);
        const FluxPoint p = inv.forward_eval(id, iq);
        const FluxPoint a = inv.forward_eval(id + h, iq), b = inv.forward_eval(id - h, iq);
        const FluxPoint c = inv.forward_eval(id, iq + h), d = inv.forward_eval(id, iq - h);
        const double tol = 1e-7 * 6e-4;
        EXPECT_NEAR(p.L_dd, (a.psi_d - b.psi_d) / (2 * h), tol) << id << ", " << iq;
        EXPECT_NEAR(p.L_qd, (a.psi_q - b.psi_q) / (2 * h), tol) << id << ", " << iq;
        EXPECT_NEAR(p.L_dq, (c.psi_d - d.psi_d) / (2 * h), tol) << id << ", " << iq;
        EXPECT_NEAR(p.L_qq, (c.psi_q - d.psi_q) / (2 * h), tol) << id << ", " << iq;
        EXPECT_GT(p.L_dd * p.L_qq - p.L_dq * p.L_qd, 0) << id << ", " << iq;
    }
    EXPECT_GT(beyond, 1000);
    // Continuity across the edges.
    for (double t = -1000; t <= 1000; t += 37) {
        for (const double e : {inv.legal().i_d_min, inv.legal().i_d_max}) {
            const FluxPoint a = inv.forward_eval(e - 1e-9, t), b = inv.forward_eval(e + 1e-9, t);
            EXPECT_NEAR(a.psi_d, b.psi_d, 1e-9);
            EXPECT_NEAR(a.psi_q, b.psi_q, 1e-9);
        }
        for (const double e : {inv.legal().i_q_min, inv.legal().i_q_max}) {
            const FluxPoint a = inv.forward_eval(t, e - 1e-9), b = inv.forward_eval(t, e + 1e-9);
            EXPECT_NEAR(a.psi_d, b.psi_d, 1e-9);
            EXPECT_NEAR(a.psi_q, b.psi_q, 1e-9);
        }
    }
}
