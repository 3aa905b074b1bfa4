// The fast depressed-quartic path (solve_depressed_quartic) against the robust general solver
// (solve_quartic, itself tested against Eigen): the controller's own MTPA and Case ii quartics
// over random machines and operating points, and random well-scaled depressed quartics.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "quartic.hpp"

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
