// Recursion 2 (the exact optimum on the flux map) on strongly saturating maps, where the torque
// along the current circle has two maxima: T_max and the commands against dense sampling of the
// feasible set (no sample may give more torque, or the commanded torque with less current), and
// the answer independent of the solver's history.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <random>

#include "control/saturated_optimal_current.hpp"
#include "flux_map_generators.hpp"
#include "machine/magnet_flux.hpp"

using namespace ipmsm;

namespace {

constexpr int kPolePairs = 4;
constexpr double kIMax = 500.0, kRs = 0.012, kPsiM = 0.078, kLd = 2.0e-4, kLq = 6.0e-4;

// A q axis that levels off (I_s), cross-saturation up to `cross`, on a grid reaching 1.3 I_max.
std::shared_ptr<const FluxMap> saturating_map(double I_s, double cross) {
    return std::make_shared<const FluxMap>(saturating_flux_map(kLd, kLq, kPsiM, I_s, cross, kIMax, 1.3 * kIMax, 53));
}

struct Sampled {
    double T_max;     // the most s T' of any feasible sample
    double I_for_T;   // the least current of any feasible sample with s T' >= T_target
    double i_d, i_q;  // where T_max is
};

// The boundary of the feasible set sampled densely: rays from the origin at n_a angles, each
// sampled at n_r radii up to I_max, every change between feasible and not bisected to the voltage
// limit; the current circle at n_c angles, every change bisected too. T_max is on that boundary.
// Also the least current of any feasible ray sample with s T' >= T_target.
Sampled sample(const MagnetFlux& flux, const OperatingLimits& lim, double s, double T_target) {
    auto within_voltage = [&](double i_d, double i_q) {
        const FluxPoint f = flux.eval(i_d, i_q);
        const double v_d = kRs * i_d - lim.omega * f.psi_q, v_q = kRs * i_q + lim.omega * f.psi_d;
        return v_d * v_d + v_q * v_q <= lim.V_max * lim.V_max;
    };
    Sampled r{-INFINITY, INFINITY, 0, 0};
    auto consider = [&](double i_d, double i_q) {
        const double T = s * flux.reduced_torque(i_d, i_q);
        if (T > r.T_max) r.T_max = T, r.i_d = i_d, r.i_q = i_q;
    };
    // Bisection between a feasible point at parameter a and an infeasible one at b of a path.
    auto bisect = [&](auto&& path, double a, double b) {
        for (int it = 0; it < 50; ++it) {
            const double m = 0.5 * (a + b);
            const auto [i_d, i_q] = path(m);
            (within_voltage(i_d, i_q) ? a : b) = m;
        }
        const auto [i_d, i_q] = path(a);
        consider(i_d, i_q);
    };
    const int n_a = 1500, n_r = 150, n_c = 20000;
    for (int a = 0; a < n_a; ++a) {
        const double c = std::cos(2 * kPi * a / n_a), sn = std::sin(2 * kPi * a / n_a);
        auto ray = [&](double rad) { return std::make_pair(rad * c, rad * sn); };
        bool prev = false;
        for (int k = 0; k <= n_r; ++k) {
            const double rad = lim.I_max * k / n_r;
            const bool in = within_voltage(rad * c, rad * sn);
            if (in) {
                consider(rad * c, rad * sn);
                if (s * flux.reduced_torque(rad * c, rad * sn) >= T_target) r.I_for_T = std::min(r.I_for_T, rad);
            }
            if (k > 0 && in != prev) {
                const double r0 = lim.I_max * (k - 1) / n_r;
                in ? bisect(ray, rad, r0) : bisect(ray, r0, rad);
            }
            prev = in;
        }
    }
    auto circle = [&](double ang) { return std::make_pair(lim.I_max * std::cos(ang), lim.I_max * std::sin(ang)); };
    bool prev = within_voltage(lim.I_max, 0.0);
    for (int j = 1; j <= n_c; ++j) {
        const double ang = 2 * kPi * j / n_c, ang0 = 2 * kPi * (j - 1) / n_c;
        const auto [i_d, i_q] = circle(ang);
        const bool in = within_voltage(i_d, i_q);
        if (in) consider(i_d, i_q);
        if (in != prev) in ? bisect(circle, ang, ang0) : bisect(circle, ang0, ang);
        prev = in;
    }
    return r;
}

}  // namespace

TEST(SaturatedOptimalCurrent, GlobalOptimumOnStronglySaturatingMaps) {
    std::mt19937_64 rng(20261124);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const double V_max = 0.95 * 355.0 / std::sqrt(3.0);
    double worst_T = 0, worst_I = 0;
    int n_cases = 0;
    for (double I_s_rel : {0.2, 0.3, 0.5, 1.0}) {
        for (double cross : {0.0, 0.15}) {
            const auto map = saturating_map(I_s_rel * kIMax, cross);
            SaturatedOptimalCurrent solver(map, kPolePairs);
            const MagnetFlux flux(*map, 0.0);
            for (int n = 0; n < 12; ++n) {
                const double w = (u(rng) < 0.5 ? -1 : 1) * kPolePairs * 1256.6 * u(rng);
                const double T_ref = (2 * u(rng) - 1) * 1.2 * 1.5 * kPolePairs * kPsiM * kIMax;
                const OperatingLimits lim{w, V_max, kIMax};
                const CurrentCommand c = solver.solve(T_ref, lim, kRs, 0.0, Recursion::optimal);
                if (!c.feasible) continue;
                ++n_cases;
                const double s = T_ref < 0 ? -1 : 1, kT = 1.5 * kPolePairs;
                const double T_cmd_red = std::min(std::abs(T_ref), c.torque_max) / kT;
                const Sampled ref = sample(flux, lim, s, T_cmd_red * (1 + 1e-9));
                const std::string ctx = "I_s " + std::to_string(I_s_rel) + " cross " + std::to_string(cross) + " w " +
                                        std::to_string(w) + " T " + std::to_string(T_ref);
                // The T_max point is feasible and gives T_max.
                const CurrentCommand top = solver.solve(s * 1e9, lim, kRs, 0.0, Recursion::optimal);
                const FluxPoint ft = flux.eval(top.i_d, top.i_q);
                ASSERT_LE(std::hypot(top.i_d, top.i_q), kIMax * (1 + 1e-6)) << ctx;
                ASSERT_LE(std::hypot(kRs * top.i_d - w * ft.psi_q, kRs * top.i_q + w * ft.psi_d), V_max * (1 + 1e-6))
                    << ctx;
                ASSERT_NEAR(s * flux.reduced_torque(top.i_d, top.i_q), c.torque_max / kT, 1e-9 * c.torque_max) << ctx;
                ASSERT_GE(c.torque_max / kT, ref.T_max * (1 - 1e-9))
                    << "a sample beats T_max: " << ctx << " region " << int(c.region) << " at " << c.i_d << ", "
                    << c.i_q << " conv " << c.converged << "; best sample at " << ref.i_d << ", " << ref.i_q;
                // The samples approach a maximum on the voltage limit only to (angle step)^2 (a lower bound
                // of T_max; the solver's T_max point is checked feasible above).
                ASSERT_LE(c.torque_max / kT - ref.T_max, 1e-3 * ref.T_max) << ctx;
                worst_T = std::max(worst_T, (c.torque_max / kT - ref.T_max) / ref.T_max);
                const double I = std::hypot(c.i_d, c.i_q);
                ASSERT_LE(I, kIMax * (1 + 1e-6)) << ctx;
                const FluxPoint f = flux.eval(c.i_d, c.i_q);
                ASSERT_LE(std::hypot(kRs * c.i_d - w * f.psi_q, kRs * c.i_q + w * f.psi_d), V_max * (1 + 1e-6)) << ctx;
                ASSERT_NEAR(s * flux.reduced_torque(c.i_d, c.i_q), T_cmd_red, 1e-6 * ref.T_max) << ctx;
                if (std::isfinite(ref.I_for_T)) {
                    ASSERT_LE(I, ref.I_for_T * (1 + 1e-9)) << "a sample needs less current: " << ctx;
                    worst_I = std::max(worst_I, (ref.I_for_T - I) / kIMax);
                }
            }
        }
    }
    std::cout << "[ measured ] " << n_cases << " cases; T_max above the best sample by at most " << worst_T
              << " rel; current below the best sample's by up to " << worst_I << " I_max\n";
    EXPECT_GT(n_cases, 80);
}

// The answer depends on the inputs only: a fresh solver and one that has been through a random
// history give the same commands, bit for bit.
TEST(SaturatedOptimalCurrent, AnswerIndependentOfHistory) {
    const auto map = saturating_map(0.3 * kIMax, 0.1);
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    SaturatedOptimalCurrent warm(map, kPolePairs);
    for (int n = 0; n < 300; ++n) {
        const double w = (2 * u(rng) - 1) * kPolePairs * 1256.6, T = (2 * u(rng) - 1) * 300.0;
        const double shift = 0.002 * (u(rng) < 0.8 ? 0.0 : u(rng));
        const OperatingLimits lim{w, 180.0 + 40 * u(rng), kIMax};
        const CurrentCommand a = warm.solve(T, lim, kRs, shift, Recursion::optimal);
        SaturatedOptimalCurrent fresh(map, kPolePairs);
        const CurrentCommand b = fresh.solve(T, lim, kRs, shift, Recursion::optimal);
        ASSERT_EQ(a.i_d, b.i_d) << n;
        ASSERT_EQ(a.i_q, b.i_q) << n;
        ASSERT_EQ(a.torque_max, b.torque_max) << n;
    }
}
