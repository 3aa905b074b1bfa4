// The closed-form (Ferrari) optimal currents of a linear machine against dense sampling of the
// feasible set: no sampled feasible point may need less current (or give more torque) than the
// solver's answer, and the best samples must come close to it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>
#include <utility>

#include "control/linear_optimal_current.hpp"

using namespace ipmsm;

namespace {

struct Case {
    LinearMachine m;
    OperatingLimits lim;
    double T_ref;
};

constexpr int kPolePairs = 4;

Case random_case(std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    Case c;
    c.m.psi_m = 0.05 + 0.05 * u(rng);
    c.m.L_d = 1e-4 + 2e-4 * u(rng);
    c.m.L_q = c.m.L_d * (1.5 + 2.0 * u(rng));
    c.m.R_s = u(rng) < 0.3 ? 0.0 : 0.05 * u(rng);
    c.lim.I_max = 300 + 300 * u(rng);
    c.lim.V_max = 150 + 100 * u(rng);
    c.lim.omega = (u(rng) < 0.5 ? -1 : 1) * 6000 * u(rng) * u(rng);
    const double T_peak = 1.5 * kPolePairs * linear::reduced_torque(c.m, -0.4 * c.lim.I_max, 0.9 * c.lim.I_max);
    c.T_ref = (2 * u(rng) - 1) * 1.3 * T_peak;
    return c;
}

bool feasible(const Case& c, double i_d, double i_q) {
    return i_d * i_d + i_q * i_q <= c.lim.I_max * c.lim.I_max &&
           linear::voltage_sq(c.m, c.lim.omega, i_d, i_q) <= c.lim.V_max * c.lim.V_max;
}

// T' max (this side: T' >= 0 on the mirrored problem) by sampling the boundary of the feasible set,
// independently of the solver's quartics: the current circle i = I (cos a, sin a) within the
// voltage limit, and the voltage ellipse v = V (cos b, sin b), i = M^-1 (v - (0, omega psi_m)),
// within the current limit; then golden-section search about the best sample (an infeasible point
// counts as -inf, so a maximum at an end of a feasible arc is found too).
double sampled_max_torque(const LinearMachine& m, const OperatingLimits& lim) {
    const double R = m.R_s, w = lim.omega, det = R * R + w * w * m.L_d * m.L_q;
    auto on_circle = [&](double a) { return std::make_pair(lim.I_max * std::cos(a), lim.I_max * std::sin(a)); };
    auto on_ellipse = [&](double b) {
        const double v_d = lim.V_max * std::cos(b), v_q = lim.V_max * std::sin(b) - w * m.psi_m;
        return std::make_pair((R * v_d + w * m.L_q * v_q) / det, (-w * m.L_d * v_d + R * v_q) / det);
    };
    auto torque_if_feasible = [&](std::pair<double, double> i) {
        const bool ok = i.first * i.first + i.second * i.second <= lim.I_max * lim.I_max * (1 + 1e-12) &&
                        linear::voltage_sq(m, w, i.first, i.second) <= lim.V_max * lim.V_max * (1 + 1e-12);
        return ok ? linear::reduced_torque(m, i.first, i.second) : -INFINITY;
    };
    double best = -INFINITY;
    constexpr int kSamples = 4000;
    constexpr double kGolden = 0.6180339887498949;
    for (int curve = 0; curve < 2; ++curve) {
        auto T = [&](double x) { return torque_if_feasible(curve == 0 ? on_circle(x) : on_ellipse(x)); };
        double x_best = 0, T_best = -INFINITY;
        for (int k = 0; k < kSamples; ++k) {
            const double x = 2 * kPi * k / kSamples;
            if (T(x) > T_best) T_best = T(x), x_best = x;
        }
        if (T_best == -INFINITY) continue;
        double a = x_best - 2 * kPi / kSamples, b = x_best + 2 * kPi / kSamples;
        for (int it = 0; it < 80; ++it) {
            const double x1 = b - kGolden * (b - a), x2 = a + kGolden * (b - a);
            if (T(x1) >= T(x2))
                b = x2;
            else
                a = x1;
            T_best = std::max({T_best, T(x1), T(x2)});
        }
        best = std::max(best, T_best);
    }
    return best;
}

}  // namespace

TEST(LinearOptimalCurrent, MeetsLimitsTorqueAndBeatsEverySample) {
    std::mt19937_64 rng(20261121);
    int by_region[5] = {0, 0, 0, 0, 0};
    double worst_current_gap = 0, worst_torque_gap = 0;
    for (int n = 0; n < 400; ++n) {
        const Case c = random_case(rng);
        const CurrentCommand cmd = linear::optimal_current(c.m, kPolePairs, c.T_ref, c.lim);
        if (!cmd.feasible) continue;
        ++by_region[static_cast<int>(cmd.region)];
        const double I = std::hypot(cmd.i_d, cmd.i_q);
        const double V = std::sqrt(linear::voltage_sq(c.m, c.lim.omega, cmd.i_d, cmd.i_q));
        ASSERT_LE(I, c.lim.I_max * (1 + 1e-9)) << n;
        ASSERT_LE(V, c.lim.V_max * (1 + 1e-9)) << n;
        const double T_cmd = std::copysign(std::min(std::abs(c.T_ref), cmd.torque_max), c.T_ref);
        ASSERT_NEAR(cmd.torque, T_cmd, 1e-9 * std::max(1.0, cmd.torque_max)) << n;

        // Sample the feasible disk on a grid, then zoom in around the best sample: the most
        // torque of this sign any sample reaches.
        const double s = c.T_ref < 0 ? -1 : 1;
        double T_best = 0, cd = 0, cq = 0, half = c.lim.I_max;
        for (int zoom = 0; zoom < 16; ++zoom) {
            const int n_grid = 100;
            const double d0 = cd, q0 = cq;
            for (int a = 0; a <= n_grid; ++a)
                for (int b = 0; b <= n_grid; ++b) {
                    const double i_d = d0 + half * (2.0 * a / n_grid - 1), i_q = q0 + half * (2.0 * b / n_grid - 1);
                    if (!feasible(c, i_d, i_q)) continue;
                    const double T = s * 1.5 * kPolePairs * linear::reduced_torque(c.m, i_d, i_q);
                    if (T > T_best) {
                        T_best = T;
                        cd = i_d;
                        cq = i_q;
                    }
                }
            half *= 0.3;  // the zoom keeps a wide window: along a limit the torque is flat near the optimum
        }
        ASSERT_GE(cmd.torque_max, T_best * (1 - 1e-12)) << "a sample beats T_max, case " << n;
        worst_torque_gap = std::max(worst_torque_gap, (cmd.torque_max - T_best) / cmd.torque_max);
        // Grid samples approach an optimum at a corner of the feasible set only slowly: 1e-4.
        // (The 1e-6 comparison is the pytest one, against scipy's constrained minimiser.)
        EXPECT_LT(cmd.torque_max - T_best, 1e-4 * cmd.torque_max) << n;
        // The T_max point itself is feasible and gives T_max.
        const auto top = linear::optimal_current(c.m, kPolePairs, s * 1e9, c.lim);
        ASSERT_LE(std::hypot(top.i_d, top.i_q), c.lim.I_max * (1 + 1e-9)) << n;
        ASSERT_LE(linear::voltage_sq(c.m, c.lim.omega, top.i_d, top.i_q), c.lim.V_max * c.lim.V_max * (1 + 1e-9)) << n;
        ASSERT_NEAR(s * top.torque, cmd.torque_max, 1e-9 * cmd.torque_max) << n;

        // Sample the torque curve T = T_cmd (i_q from 0 to I_max): no feasible sample needs less current.
        if (std::abs(T_cmd) < 1e-9) continue;
        const double Tr = T_cmd / (1.5 * kPolePairs);
        double I_best = INFINITY;
        for (int k = 1; k <= 200000; ++k) {
            const double i_q = s * c.lim.I_max * k / 200000.0;
            const double i_d = (Tr / i_q - c.m.psi_m) / (c.m.L_d - c.m.L_q);
            if (feasible(c, i_d, i_q)) I_best = std::min(I_best, std::hypot(i_d, i_q));
        }
        if (I_best < INFINITY) {
            ASSERT_LE(I, I_best * (1 + 1e-9)) << "a sample on the torque curve needs less current, case " << n;
            worst_current_gap = std::max(worst_current_gap, (I_best - I) / I);
        }
    }
    std::cout << "[ measured ] regions 0..4: " << by_region[0] << " " << by_region[1] << " " << by_region[2] << " "
              << by_region[3] << " " << by_region[4] << "; worst T_max - best sample: " << worst_torque_gap
              << " rel; worst best-sample current - solver: " << worst_current_gap << " rel\n";
    for (int r = 1; r <= 4; ++r) EXPECT_GT(by_region[r], 5) << "region " << r << " barely exercised";
}

TEST(LinearOptimalCurrent, MirrorSymmetryOfTorqueAndSpeedSigns) {
    const LinearMachine m{0.078, 2e-4, 6e-4, 0.012};
    for (double w : {0.0, 1500.0, 3000.0, 5000.0}) {
        for (double T : {50.0, 150.0, 400.0}) {
            const auto a = linear::optimal_current(m, 4, T, {w, 195, 500});
            const auto b = linear::optimal_current(m, 4, -T, {-w, 195, 500});
            EXPECT_NEAR(a.i_d, b.i_d, 1e-9);
            EXPECT_NEAR(a.i_q, -b.i_q, 1e-9);
            EXPECT_NEAR(a.torque_max, b.torque_max, 1e-9);
        }
    }
}

TEST(LinearOptimalCurrent, ZeroTorqueAboveCornerSpeedWeakensTheField) {
    const LinearMachine m{0.078, 2e-4, 6e-4, 0.012};
    const double w = 4 * 1200.0;  // omega psi_m = 374 V > V_max
    const auto c = linear::optimal_current(m, 4, 0.0, {w, 195, 500});
    EXPECT_EQ(c.region, Region::zero_torque);
    EXPECT_LT(c.i_d, -1.0);
    EXPECT_NEAR(c.i_q, 0.0, 1e-12);
    EXPECT_NEAR(std::sqrt(linear::voltage_sq(m, w, c.i_d, c.i_q)), 195.0, 1e-6);
}

TEST(LinearOptimalCurrent, AboveMaximumSpeedIsReportedInfeasible) {
    const LinearMachine m{0.2, 2e-4, 6e-4, 0.0};  // psi_m / L_d = 1000 A > I_max
    const auto c = linear::optimal_current(m, 4, 100.0, {4 * 5000.0, 195, 500});
    EXPECT_FALSE(c.feasible);
    EXPECT_EQ(c.torque_max, 0.0);
    EXPECT_TRUE(std::isfinite(c.i_d) && std::isfinite(c.i_q));
}

// T_max against the sampled boundary of the feasible set (sampled_max_torque) on random machines
// (R_s up to 0.05 ohm), speeds and torque signs.
TEST(LinearOptimalCurrent, TorqueLimitMatchesTheSampledBoundary) {
    std::mt19937_64 rng(20261122);
    int compared = 0;
    double worst = 0;
    for (int n = 0; n < 3000; ++n) {
        const Case c = random_case(rng);
        const CurrentCommand cmd = linear::optimal_current(c.m, kPolePairs, c.T_ref, c.lim);
        const double s = c.T_ref < 0 ? -1 : 1;
        const double T_ref = sampled_max_torque(c.m, {s * c.lim.omega, c.lim.V_max, c.lim.I_max});
        if (!(T_ref > 0)) continue;
        ++compared;
        const double T_max = 1.5 * kPolePairs * T_ref;
        worst = std::max(worst, std::abs(cmd.torque_max - T_max) / T_max);
        ASSERT_NEAR(cmd.torque_max, T_max, 1e-9 * T_max) << n;
    }
    std::cout << "[ measured ] " << compared << " cases; worst relative difference of T_max " << worst << "\n";
    EXPECT_GT(compared, 2500);
}

// Near the speed where the MTPV point enters the current circle, the lossless (R_s = 0) machine
// names the other limit than the machine with R_s: the two limits' points are close there. Speeds
// swept across that band, both directions of rotation, both torque signs, clamped commands:
// T_max against the sampled boundary, the command at T_max's point with its region.
TEST(LinearOptimalCurrent, TorqueLimitWhereTheLosslessEstimateNamesTheOtherLimit) {
    const LinearMachine m{0.05, 1.5e-4, 4.5e-4, 0.05};  // psi_m / L_d < I_max; a large R_s: a wide band
    LinearMachine lossless = m;
    lossless.R_s = 0.0;
    const double V_max = 200.0, I_max = 400.0;
    int disagree = 0, compared = 0;
    for (int k = 0; k <= 2000; ++k) {
        const double w = 1500.0 + 10500.0 * k / 2000.0;  // electrical rad/s
        for (double sw : {-1.0, 1.0}) {
            for (double sT : {-1.0, 1.0}) {
                const OperatingLimits lim{sw * w, V_max, I_max};
                const OperatingLimits mirrored{sT * sw * w, V_max, I_max};
                const linear::Limit top = linear::max_torque(m, mirrored);
                if (!top.feasible || top.region == Region::mtpa) continue;
                disagree += linear::max_torque(lossless, mirrored).region != top.region;
                ++compared;
                const CurrentCommand cmd = linear::optimal_current(m, kPolePairs, sT * 1e6, lim);
                const double T_max = 1.5 * kPolePairs * sampled_max_torque(m, mirrored);
                ASSERT_NEAR(cmd.torque_max, T_max, 1e-9 * T_max) << w << " " << sw << " " << sT;
                ASSERT_NEAR(cmd.i_d, top.point.i_d, 1e-9 * I_max) << w << " " << sw << " " << sT;
                ASSERT_NEAR(cmd.i_q, sT * top.point.i_q, 1e-9 * I_max) << w << " " << sw << " " << sT;
                ASSERT_EQ(cmd.region, top.region) << w << " " << sw << " " << sT;
            }
        }
    }
    std::cout << "[ measured ] " << compared << " clamped commands in field weakening; the lossless limit differs in "
              << disagree << "\n";
    EXPECT_GT(disagree, 10);  // the band is exercised
}

// Nearly non-salient machines (|L_d - L_q| / L from 1e-9 to 3e-2, both signs): Case ii's quartic in
// i_q degenerates there (a double root), and Newton on the torque curve and the ellipse takes
// over. Every command within both limits, giving its torque, and no feasible point sampled along
// its torque curve (parametrised by i_d) needs less current.
TEST(LinearOptimalCurrent, NearlyNonSalientMachines) {
    std::mt19937_64 rng(20261125);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    int by_region[5] = {0, 0, 0, 0, 0};
    for (int n = 0; n < 3000; ++n) {
        Case c = random_case(rng);
        const double rel = std::pow(10.0, -9.0 + 7.5 * u(rng));
        c.m.L_q = c.m.L_d * (1 + (u(rng) < 0.5 ? -1 : 1) * rel);
        const CurrentCommand cmd = linear::optimal_current(c.m, kPolePairs, c.T_ref, c.lim);
        if (!cmd.feasible) continue;
        ++by_region[static_cast<int>(cmd.region)];
        const double I = std::hypot(cmd.i_d, cmd.i_q);
        ASSERT_LE(I, c.lim.I_max * (1 + 1e-9)) << n;
        ASSERT_LE(std::sqrt(linear::voltage_sq(c.m, c.lim.omega, cmd.i_d, cmd.i_q)), c.lim.V_max * (1 + 1e-9)) << n;
        const double T_cmd = std::copysign(std::min(std::abs(c.T_ref), cmd.torque_max), c.T_ref);
        ASSERT_NEAR(cmd.torque, T_cmd, 1e-9 * std::max(1.0, cmd.torque_max)) << n;
        ASSERT_NEAR(1.5 * kPolePairs * linear::reduced_torque(c.m, cmd.i_d, cmd.i_q), T_cmd,
                    1e-9 * std::max(1.0, cmd.torque_max))
            << n;
        if (n % 10 != 0 || std::abs(T_cmd) < 1e-9) continue;  // the sampling on every tenth case
        const double Tr = T_cmd / (1.5 * kPolePairs), dL = c.m.L_d - c.m.L_q;
        double I_best = INFINITY;
        for (int k = 0; k <= 100000; ++k) {
            const double i_d = c.lim.I_max * (2.0 * k / 100000 - 1), i_q = Tr / (c.m.psi_m + dL * i_d);
            if (feasible(c, i_d, i_q)) I_best = std::min(I_best, std::hypot(i_d, i_q));
        }
        if (I_best < INFINITY) {
            ASSERT_LE(I, I_best * (1 + 1e-9)) << "a sample on the torque curve needs less current, case " << n;
        }
    }
    for (int r = 1; r <= 4; ++r) EXPECT_GT(by_region[r], 20) << "region " << r;
}

// A reluctance machine (psi_m = 0: Case ii's quartic is biquadratic) in field weakening, both
// torque signs and directions: the command gives the torque asked for within both limits.
TEST(LinearOptimalCurrent, ReluctanceMachineInFieldWeakening) {
    const LinearMachine m{0.0, 2e-4, 6e-4, 0.012};
    const double V_max = 195.0, I_max = 500.0;
    int voltage_limited = 0;
    for (double w : {-6000.0, -3000.0, 3000.0, 6000.0}) {
        for (double T : {-40.0, -7.0, 7.0, 40.0}) {
            const CurrentCommand c = linear::optimal_current(m, kPolePairs, T, {w, V_max, I_max});
            voltage_limited += c.region == Region::voltage_limit;
            ASSERT_LE(std::hypot(c.i_d, c.i_q), I_max * (1 + 1e-9)) << w << " " << T;
            ASSERT_LE(std::sqrt(linear::voltage_sq(m, w, c.i_d, c.i_q)), V_max * (1 + 1e-9)) << w << " " << T;
            const double T_cmd = std::copysign(std::min(std::abs(T), c.torque_max), T);
            ASSERT_NEAR(c.torque, T_cmd, 1e-9 * c.torque_max) << w << " " << T;
            ASSERT_NEAR(1.5 * kPolePairs * linear::reduced_torque(m, c.i_d, c.i_q), T_cmd, 1e-9 * c.torque_max)
                << w << " " << T;
        }
    }
    EXPECT_GT(voltage_limited, 4);
}

// Large R_s against omega L while braking (the mirrored speed negative): the limit quartics have
// other stationary points and intersections (a torque minimum on the ellipse, an intersection
// where the voltage limit does not bind), which must not be taken for T_max. Two cases found by a review, then random machines with
// R_s up to three times omega L_d: T_max against the sampled boundary.
TEST(LinearOptimalCurrent, TorqueLimitWithLargeResistanceAgainstOmegaL) {
    struct Known {
        LinearMachine m;
        double omega, V_max, I_max, T_ref;
    };
    const Known known[] = {{{0.7876, 0.005147, 0.023552, 28.44}, -2048.76, 485.63, 205.74, 528.9},
                           {{0.08383, 0.008555, 0.021822, 1.26}, -72.2, 10.28, 13.25, 1e3}};
    for (const Known& k : known) {
        const CurrentCommand c = linear::optimal_current(k.m, kPolePairs, k.T_ref, {k.omega, k.V_max, k.I_max});
        const double T_max = 1.5 * kPolePairs * sampled_max_torque(k.m, {k.omega, k.V_max, k.I_max});
        ASSERT_NEAR(c.torque_max, T_max, 1e-9 * T_max) << k.m.R_s;
    }
    std::mt19937_64 rng(20261124);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    int compared = 0;
    for (int n = 0; n < 3000; ++n) {
        Case c = random_case(rng);
        const double w = (u(rng) < 0.5 ? -1 : 1) * (300 + 6000 * u(rng));
        c.lim.omega = w;
        c.m.R_s = 3.0 * u(rng) * std::abs(w) * c.m.L_d;
        const double s = c.T_ref < 0 ? -1 : 1;
        const double T_ref = sampled_max_torque(c.m, {s * w, c.lim.V_max, c.lim.I_max});
        if (!(T_ref > 0)) continue;
        ++compared;
        const CurrentCommand cmd = linear::optimal_current(c.m, kPolePairs, c.T_ref, c.lim);
        const double T_max = 1.5 * kPolePairs * T_ref;
        ASSERT_NEAR(cmd.torque_max, T_max, 1e-9 * T_max) << n;
    }
    EXPECT_GT(compared, 1500);
}

// A kept solver gives the same commands, bit for bit, as a fresh solver per call, whatever the
// sequence of machines and current limits (the answer depends on the inputs only).
TEST(LinearOptimalCurrent, KeptSolverMatchesAFreshOneAsTheMachineAndCurrentLimitChange) {
    std::mt19937_64 rng(20261123);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    Case first = random_case(rng);
    linear::CommandSolver kept(kPolePairs);
    for (int n = 0; n < 20000; ++n) {
        Case c = random_case(rng);
        if (u(rng) < 0.5) c.m = first.m;                  // runs of one machine, and changes
        if (u(rng) < 0.5) c.lim.I_max = first.lim.I_max;  // runs of one limit, and changes
        if (u(rng) < 0.01) first = c;
        const CurrentCommand a = kept(c.m, c.T_ref, c.lim),
                             b = linear::optimal_current(c.m, kPolePairs, c.T_ref, c.lim);
        ASSERT_EQ(a.i_d, b.i_d) << n;
        ASSERT_EQ(a.i_q, b.i_q) << n;
        ASSERT_EQ(a.torque_max, b.torque_max) << n;
        ASSERT_EQ(a.region, b.region) << n;
    }
}
