// The fast depressed-quartic path (solve_depressed_quartic) against the robust general solver
// (solve_quartic, itself tested against Eigen): the controller's own MTPA and Case ii quartics
// over random machines and operating points, and random well-scaled depressed quartics.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>

#include "numerics/quartic.hpp"

using namespace ipmsm;

namespace {

double rel_residual(double p, double q, double r, double x) {
    const double f = ((x * x + p) * x + q) * x + r;
    const double scale = x * x * x * x + std::abs(p) * x * x + std::abs(q * x) + std::abs(r);
    return scale > 0 ? std::abs(f) / scale : std::abs(f);
}

// Every root of one solver is within tol of a root of the other, and the counts agree.
void expect_same_roots(const RealRoots& a, const RealRoots& b, double tol, const char* what, int n) {
    ASSERT_EQ(a.count, b.count) << what << " case " << n;
    for (int k = 0; k < a.count; ++k)
        ASSERT_NEAR(a.root[k], b.root[k], tol * std::max(1.0, std::abs(b.root[k]))) << what << " case " << n;
}

}  // namespace

TEST(DepressedQuartic, ControllerQuarticsMatchTheRobustSolver) {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> u(0, 1);
    double worst = 0;
    for (int n = 0; n < 200000; ++n) {
        const double psi = 0.02 + 0.1 * u(rng), L_d = 5e-5 + 5e-4 * u(rng), L_q = L_d * (1.2 + 3 * u(rng));
        const double R = 0.1 * u(rng) * u(rng), w = (2 * u(rng) - 1) * 8000, V = 50 + 300 * u(rng);
        const double T = 1e-3 + 150 * u(rng) * u(rng), dL = L_d - L_q;
        // MTPA: dL^2 x^4 + psi T x - T^2
        const double k = 1 / (dL * dL);
        const RealRoots f1 = solve_depressed_quartic(0, psi * T * k, -T * T * k);
        const RealRoots g1 = solve_quartic(1, 0, 0, psi * T * k, -T * T * k);
        expect_same_roots(f1, g1, 1e-10, "MTPA", n);
        // Case ii
        const double zq = R * R + w * w * L_q * L_q;
        const double a4 = dL * dL * zq, a2 = psi * psi * zq + 2 * R * w * dL * dL * T - V * V * dL * dL;
        const double a1 = -2 * psi * T * (R * R + w * w * L_d * L_q), a0 = T * T * (R * R + w * w * L_d * L_d);
        const RealRoots f2 = solve_depressed_quartic(a2 / a4, a1 / a4, a0 / a4);
        const RealRoots g2 = solve_quartic(1, 0, a2 / a4, a1 / a4, a0 / a4);
        // Near a double root (the torque curve tangent to the ellipse) the count is ill-conditioned.
        if (f2.count == g2.count) expect_same_roots(f2, g2, 1e-7, "Case ii", n);
        for (int j = 0; j < f2.count; ++j) worst = std::max(worst, rel_residual(a2 / a4, a1 / a4, a0 / a4, f2.root[j]));
    }
    std::cout << "[ measured ] worst relative residual on Case ii quartics: " << worst << "\n";
    EXPECT_LT(worst, 1e-13);
}

TEST(DepressedQuartic, KnownRootsAndNoNaN) {
    std::mt19937_64 rng(12);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int n = 0; n < 200000; ++n) {
        // Four real roots summing to zero (depressed): x1, x2, x3, -(x1+x2+x3), separated.
        double x[4] = {100 * u(rng), 100 * u(rng), 100 * u(rng), 0};
        x[3] = -(x[0] + x[1] + x[2]);
        std::sort(x, x + 4);
        if (x[1] - x[0] < 1 || x[2] - x[1] < 1 || x[3] - x[2] < 1) continue;
        const double p = x[0] * x[1] + x[0] * x[2] + x[0] * x[3] + x[1] * x[2] + x[1] * x[3] + x[2] * x[3];
        const double q = -(x[0] * x[1] * x[2] + x[0] * x[1] * x[3] + x[0] * x[2] * x[3] + x[1] * x[2] * x[3]);
        const double r = x[0] * x[1] * x[2] * x[3];
        const RealRoots f = solve_depressed_quartic(p, q, r);
        ASSERT_EQ(f.count, 4) << n;
        for (int k = 0; k < 4; ++k) ASSERT_NEAR(f.root[k], x[k], 1e-9 * 300) << n;
    }
    const double bad[] = {0.0, 1e300, -1e300, 1e-300, 1.0, -1.0};
    for (double p : bad)
        for (double q : bad)
            for (double r : bad) {
                const RealRoots f = solve_depressed_quartic(p, q, r);
                for (int k = 0; k < f.count; ++k) ASSERT_TRUE(std::isfinite(f.root[k])) << p << " " << q << " " << r;
            }
    EXPECT_EQ(solve_depressed_quartic(NAN, 0, 0).count, 0);
    // Biquadratic: x^4 - 5x^2 + 4 = (x^2-1)(x^2-4)
    const RealRoots b = solve_depressed_quartic(-5, 0, 4);
    ASSERT_EQ(b.count, 4);
    EXPECT_NEAR(b.root[0], -2, 1e-14);
    EXPECT_NEAR(b.root[3], 2, 1e-14);
}

// The general quartics of the depressed path (centred_quartic_roots, the controller's
// tan-half-angle quartics) against the robust solver: random quartics with four or two real roots
// of order 1 around a random centroid within its range, each root polished once as the
// controller does. Also: far-off centroids (a root near infinity) are handed to the robust solver.
TEST(CentredQuartic, MatchesTheRobustSolverAfterOnePolish) {
    const double kCentre = 16;  // centroids in [-16, 16], clusters of width 2 (gaps >= 1e-3)
    std::mt19937_64 rng(13);
    std::uniform_real_distribution<double> u(-1, 1);
    double worst = 0, worst_root = 0;
    int compared = 0;
    for (int n = 0; n < 200000; ++n) {
        const double centre = kCentre * u(rng), a = std::ldexp(1.0 + 0.5 * u(rng), static_cast<int>(40 * u(rng)));
        double x[4] = {centre + u(rng), centre + u(rng), centre + u(rng), centre + u(rng)};
        std::sort(x, x + 4);
        if (x[1] - x[0] < 1e-3 || x[2] - x[1] < 1e-3 || x[3] - x[2] < 1e-3) continue;
        double c[5];
        if (n % 2 == 0) {  // four real roots: a prod (x - x_i)
            const double e1 = x[0] + x[1] + x[2] + x[3];
            const double e2 = x[0] * x[1] + x[0] * x[2] + x[0] * x[3] + x[1] * x[2] + x[1] * x[3] + x[2] * x[3];
            const double e3 = x[0] * x[1] * x[2] + x[0] * x[1] * x[3] + x[0] * x[2] * x[3] + x[1] * x[2] * x[3];
            const double e4 = x[0] * x[1] * x[2] * x[3];
            const double cc[5] = {a, -a * e1, a * e2, -a * e3, a * e4};
            std::copy(cc, cc + 5, c);
        } else {  // two real roots x0, x3 and a complex pair centre +- i: a (x-x0)(x-x3)((x-centre)^2+1)
            const double s = x[0] + x[3], pr = x[0] * x[3], qs = 2 * centre, qp = centre * centre + 1;
            const double cc[5] = {a, -a * (s + qs), a * (pr + s * qs + qp), -a * (pr * qs + s * qp), a * pr * qp};
            std::copy(cc, cc + 5, c);
        }
        const RealRoots fast = centred_quartic_roots(c[0], c[1], c[2], c[3], c[4]);
        const RealRoots robust = solve_quartic(c[0], c[1], c[2], c[3], c[4]);
        if (fast.count != robust.count) continue;  // only near double roots (gap >= 1e-3 here: never seen)
        ++compared;
        double polished[4];
        for (int k = 0; k < fast.count; ++k) polished[k] = newton_step(c, fast.root[k]).root();
        // Ascending, as the robust solver's roots (an insertion sort: std::sort on this 4-array
        // trips GCC 12's -Warray-bounds).
        for (int i = 1; i < fast.count; ++i)
            for (int j = i; j > 0 && polished[j] < polished[j - 1]; --j) std::swap(polished[j], polished[j - 1]);
        // Backward error of each polished root: |p(x)| / sum |c_i| |x|^i (the robust solver's
        // own measure, ~1e-15 on its test classes).
        for (int k = 0; k < fast.count; ++k) {
            const double y = polished[k], ay = std::abs(y);
            const double f = quartic_value(c, y).f;
            const double scale =
                (((std::abs(c[0]) * ay + std::abs(c[1])) * ay + std::abs(c[2])) * ay + std::abs(c[3])) * ay +
                std::abs(c[4]);
            worst = std::max(worst, std::abs(f) / scale);
            worst_root = std::max(worst_root, std::abs(y - robust.root[k]) / std::max(1.0, std::abs(robust.root[k])));
        }
    }
    std::cout << "[ measured ] " << compared << " quartics; after one polish: worst backward error " << worst
              << ", worst relative difference from the robust solver " << worst_root << "\n";
    EXPECT_GT(compared, 90000);
    EXPECT_LT(worst, 1e-14);
    // A root near infinity: the robust solver's answer.
    const RealRoots far = centred_quartic_roots(1e-9, 1.0, -6.0, 11.0, -6.0);
    const RealRoots ref = solve_quartic(1e-9, 1.0, -6.0, 11.0, -6.0);
    ASSERT_EQ(far.count, ref.count);
    for (int k = 0; k < ref.count; ++k) EXPECT_EQ(far.root[k], ref.root[k]);
}
