// Least-loss commands (control/least_loss.hpp, control/least_loss_linear.hpp) against brute force
// written here: on a linear machine with alpha = 2 the quartic's point against a dense search along
// the shaft-torque curve (exact on each ray: the curve is a conic); on the linear and a saturating
// map the solver on the map against the same search (rays bisected, each ray's first crossing),
// in four quadrants, with and without the limits binding.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <memory>
#include <random>
#include <string>

#include "control/least_loss.hpp"
#include "control/least_loss_linear.hpp"
#include "control/saturated_optimal_current.hpp"
#include "flux_map_generators.hpp"
#include "machine/flux_map.hpp"
#include "machine/machine.hpp"
#include "machine/magnet_flux.hpp"
#include "source_tree.hpp"

using namespace ipmsm;

namespace {

constexpr int kP = 4;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kIMax = 500.0, kRs = 0.012, kPsiM = 0.078, kLd = 2.0e-4, kLq = 6.0e-4;
const IronLossModel kIron{1.06664735685, 2.0, 0.00581807649193, 0.0780669432093};
const InverterParams kInverter{};

struct Brute {
    double i_d = NAN, i_q = NAN, P = INFINITY;  // the least loss found
};

// Dense search along the curve T_shaft(i) = T: rays at n angles, on each the first crossing by
// bisection of the shaft torque from the origin outwards (sampled at n_r radii), the full loss
// (P_cu + P_fe + P_inv) there, within the limits; then golden section in the angle around the best.
Brute brute_force(const MagnetFlux& flux, const DriveLoss& loss, const OperatingLimits& lim, double T, int n = 3000,
                  int n_r = 400) {
    const double kT = 1.5 * kP;
    auto shaft = [&](double i_d, double i_q) {
        const FluxPoint f = flux.eval(i_d, i_q);
        const double T_e = kT * (f.psi_d * i_q - f.psi_q * i_d);
        return T_e - loss.drag(loss.iron().power(kP, loss.w_m(), f.psi_d, f.psi_q));
    };
    auto full = [&](double i_d, double i_q, bool& ok) {
        const FluxPoint f = flux.eval(i_d, i_q);
        const double vd = loss.R() * i_d - lim.omega * f.psi_q, vq = loss.R() * i_q + lim.omega * f.psi_d;
        ok = vd * vd + vq * vq <= lim.V_max * lim.V_max && i_d * i_d + i_q * i_q <= lim.I_max * lim.I_max;
        const double T_e = kT * (f.psi_d * i_q - f.psi_q * i_d);
        return loss.at(i_d, i_q, f.psi_d, f.psi_q, T_e).total();
    };
    auto at_angle = [&](double a, double& i_d, double& i_q, bool& ok) {
        const double c = std::cos(a), s = std::sin(a);
        double r0 = 0.0, h0 = shaft(0, 0) - T;
        for (int k = 1; k <= n_r; ++k) {
            double r1 = lim.I_max * k / n_r, h1 = shaft(r1 * c, r1 * s) - T;
            if ((h0 <= 0) != (h1 <= 0)) {
                for (int it = 0; it < 80; ++it) {
                    const double m = 0.5 * (r0 + r1), hm = shaft(m * c, m * s) - T;
                    ((hm <= 0) == (h0 <= 0) ? r0 : r1) = m;
                }
                i_d = 0.5 * (r0 + r1) * c, i_q = 0.5 * (r0 + r1) * s;
                return full(i_d, i_q, ok);
            }
            r0 = r1, h0 = h1;
        }
        ok = false;
        return kInf;
    };
    Brute b;
    double a_best = 0;
    for (int j = 0; j < n; ++j) {
        const double a = 2.0 * kPi * j / n;
        double i_d, i_q;
        bool ok;
        const double P = at_angle(a, i_d, i_q, ok);
        if (ok && P < b.P) b = {i_d, i_q, P}, a_best = a;
    }
    double lo = a_best - 2.0 * kPi / n, hi = a_best + 2.0 * kPi / n;
    for (int it = 0; it < 100; ++it) {
        const double m1 = lo + 0.382 * (hi - lo), m2 = lo + 0.618 * (hi - lo);
        double d1, q1, d2, q2;
        bool ok1, ok2;
        const double P1 = at_angle(m1, d1, q1, ok1), P2 = at_angle(m2, d2, q2, ok2);
        if (ok1 && P1 < b.P) b = {d1, q1, P1};
        if (ok2 && P2 < b.P) b = {d2, q2, P2};
        ((ok1 ? P1 : INFINITY) < (ok2 ? P2 : INFINITY) ? hi : lo) =
            (ok1 ? P1 : INFINITY) < (ok2 ? P2 : INFINITY) ? m2 : m1;
    }
    return b;
}

TEST(LeastLossLinear, QuarticEqualsBruteForceOnALinearMachine) {
    // alpha = 2: the quartic of each majorise-minimise step, iterated, against the search along
    // the curve (the curve is a conic: each ray's crossing in closed form).
    const least_loss_linear::Machine m{kPsiM, kLd, kLq, 1.5 * kP};
    for (double rpm : {1000.0, 4000.0, 6000.0, 9000.0}) {
        for (double T : {-150.0, -40.0, -5.0, 3.0, 20.0, 80.0, 200.0}) {
            const double w = rpm * kPi / 30.0, f = kP * w / (2 * kPi);
            const InverterLossModel inv(kInverter, 355.0);
            const double K = (kIron.k_h * f + kIron.k_e * f * f) / (kIron.psi_ref * kIron.psi_ref);
            const double e = 1.0 + inv.k_ac();
            const least_loss_linear::Loss l{1.5 * kRs * e + inv.k_square(), inv.k_linear(), e, K, K / w};
            const least_loss_linear::Result r = least_loss_linear::solve(m, l, T, 50.0);
            ASSERT_TRUE(r.found);
            // brute force: J along the curve, each ray's crossing the conic's smallest positive root
            auto J_at = [&](double a, double& i_d, double& i_q) {
                const double c = std::cos(a), s = std::sin(a);
                // h(r) = kT (psi_m r s + dL r^2 c s) - kappa ((psi_m + L_d r c)^2 + L_q^2 r^2 s^2) = T
                const double A2 = m.kT * (kLd - kLq) * c * s - l.kappa * (kLd * kLd * c * c + kLq * kLq * s * s);
                const double A1 = m.kT * kPsiM * s - l.kappa * 2.0 * kPsiM * kLd * c;
                const double A0 = -l.kappa * kPsiM * kPsiM - T;
                double rr = INFINITY;
                if (A2 == 0.0) {
                    if (A1 != 0.0 && -A0 / A1 > 0) rr = -A0 / A1;
                } else {
                    const double disc = A1 * A1 - 4 * A2 * A0;
                    if (disc >= 0) {
                        const double sq = std::sqrt(disc);
                        const double q = -0.5 * (A1 + std::copysign(sq, A1));
                        for (double x : {q / A2, A0 / q})
                            if (x > 0 && x < rr) rr = x;
                    }
                }
                if (!(rr < 1e5)) return kInf;
                i_d = rr * c, i_q = rr * s;
                const double pd = kPsiM + kLd * i_d, pq = kLq * i_q;
                return l.a * rr * rr + l.b * rr + l.e * K * (pd * pd + pq * pq);
            };
            double best = INFINITY, a_best = 0, bd = 0, bq = 0;
            const int n = 20000;
            for (int j = 0; j < n; ++j) {
                double i_d, i_q;
                const double a = 2 * kPi * j / n, J = J_at(a, i_d, i_q);
                if (J < best) best = J, a_best = a, bd = i_d, bq = i_q;
            }
            double lo = a_best - 2 * kPi / n, hi = a_best + 2 * kPi / n;
            for (int it = 0; it < 200; ++it) {
                const double m1 = lo + 0.381966 * (hi - lo), m2 = hi - 0.381966 * (hi - lo);
                double d1, q1, d2, q2;
                const double J1 = J_at(m1, d1, q1), J2 = J_at(m2, d2, q2);
                if (J1 < best) best = J1, bd = d1, bq = q1;
                if (J2 < best) best = J2, bd = d2, bq = q2;
                (J1 < J2 ? hi : lo) = J1 < J2 ? m2 : m1;
            }
            EXPECT_NEAR(r.J, best, 1e-9 * best) << rpm << " r/min, " << T << " N.m";
            EXPECT_NEAR(r.i_d, bd, 1e-4) << rpm << " r/min, " << T << " N.m";
            EXPECT_NEAR(r.i_q, bq, 1e-4) << rpm << " r/min, " << T << " N.m";
            EXPECT_GE(r.J, best * (1 - 1e-12)) << "below the brute force: not on the curve?";
        }
    }
}

struct Case {
    double rpm, T_frac, u_dc;
};

void check_against_brute_force(const std::shared_ptr<const FluxMap>& map, double shift, std::mt19937& rng, int n) {
    SaturatedOptimalCurrent em(map, kP);
    LeastLoss ll(map, kP, false);
    const MagnetFlux flux(*map, shift);
    std::uniform_real_distribution<double> U(0.0, 1.0);
    for (int k = 0; k < n; ++k) {
        const double rpm = (U(rng) < 0.5 ? -1 : 1) * 12000.0 * U(rng);
        const double w = rpm * kPi / 30.0;
        const double u_dc = 300.0 + 100.0 * U(rng);
        const OperatingLimits lim{kP * w, 0.95 * u_dc / std::sqrt(3.0), kIMax};
        const DriveLoss loss(kIron, kInverter, kP, w, kRs, u_dc);
        const double side = U(rng) < 0.5 ? -1.0 : 1.0;
        const CurrentCommand top = em.solve(side * 1e30, lim, kRs, shift, Recursion::optimal);
        if (!top.feasible) continue;
        const double T = side * top.torque_max * 1.1 * U(rng);
        const CurrentCommand least_current = em.solve(T, lim, kRs, shift, Recursion::optimal);
        const CurrentPoint hint{least_current.i_d, least_current.i_q};
        const LeastLossResult r = ll.solve(T, lim, flux, loss, top, k % 2 ? &hint : nullptr);
        SCOPED_TRACE(::testing::Message() << rpm << " r/min, T = " << T << " N.m, u_dc = " << u_dc);
        ASSERT_TRUE(r.cmd.feasible);
        EXPECT_LE(std::hypot(r.cmd.i_d, r.cmd.i_q), kIMax * (1 + 1e-9));
        const double T_cmd = side * std::min(std::abs(T), r.cmd.torque_max);
        EXPECT_NEAR(r.cmd.torque, T_cmd, 1e-6 * std::max(1.0, r.cmd.torque_max));
        if (std::abs(T) >= r.cmd.torque_max) continue;
        const Brute b = brute_force(flux, loss, lim, T);
        EXPECT_LE(r.loss.total(), b.P * (1 + 1e-4)) << "brute force at (" << b.i_d << ", " << b.i_q << ") A, command ("
                                                    << r.cmd.i_d << ", " << r.cmd.i_q << ") A";
        EXPECT_GE(r.loss.total(), b.P * (1 - 1e-4)) << "less than the brute force";
    }
}

TEST(LeastLoss, LinearMapAgainstBruteForce) {
    auto map = std::make_shared<const FluxMap>(linear_flux_map(kLd, kLq, kPsiM, 1.3 * kIMax, 41));
    std::mt19937 rng(1);
    check_against_brute_force(map, 0.0, rng, 20);
}

TEST(LeastLoss, SaturatingMapAgainstBruteForce) {
    auto map =
        std::make_shared<const FluxMap>(saturating_flux_map(kLd, kLq, kPsiM, 200.0, 0.15, kIMax, 1.3 * kIMax, 53));
    std::mt19937 rng(2);
    check_against_brute_force(map, -0.005, rng, 20);
}

TEST(LeastLoss, MapSolverEqualsTheQuarticOnALinearMap) {
    auto map = std::make_shared<const FluxMap>(linear_flux_map(kLd, kLq, kPsiM, 1.3 * kIMax, 41));
    SaturatedOptimalCurrent em(map, kP);
    LeastLoss ll(map, kP, false);
    const MagnetFlux flux(*map, 0.0);
    const least_loss_linear::Machine m{kPsiM, kLd, kLq, 1.5 * kP};
    for (double rpm : {2000.0, 4000.0, -3000.0}) {
        for (double T : {-60.0, -10.0, 5.0, 30.0, 90.0}) {
            const double w = rpm * kPi / 30.0;
            const OperatingLimits lim{kP * w, 1e4, kIMax};  // no voltage limit
            const DriveLoss loss(kIron, kInverter, kP, w, kRs, 355.0);
            const CurrentCommand top = em.solve(T < 0 ? -1e30 : 1e30, lim, kRs, 0.0, Recursion::optimal);
            const LeastLossResult r = ll.solve(T, lim, flux, loss, top);
            const double f = kP * std::abs(w) / (2 * kPi);
            const double K = (kIron.k_h * f + kIron.k_e * f * f) / (kIron.psi_ref * kIron.psi_ref);
            const InverterLossModel inv(kInverter, 355.0);
            const double e = 1.0 + inv.k_ac();
            const least_loss_linear::Loss l{1.5 * kRs * e + inv.k_square(), inv.k_linear(), e, K, K / w};
            const least_loss_linear::Result q = least_loss_linear::solve(m, l, T, 50.0);
            EXPECT_NEAR(r.cmd.i_d, q.i_d, 1e-6) << rpm << " r/min " << T << " N.m";
            EXPECT_NEAR(r.cmd.i_q, q.i_q, 1e-6) << rpm << " r/min " << T << " N.m";
        }
    }
}

// The most shaft torque s h within |i| <= I_max and |v| <= V_max by search: the current circle
// at n angles, and on each of n rays the voltage limit's first crossing (bisection) inside it,
// each refined by golden section in the angle around its best; and a polar grid of the disk.
double brute_max_shaft_torque(const MagnetFlux& flux, const DriveLoss& loss, const OperatingLimits& lim, double s,
                              int n = 4000) {
    const double kT = 1.5 * kP, V2 = lim.V_max * lim.V_max;
    auto h = [&](double i_d, double i_q, bool& ok) {
        const FluxPoint f = flux.eval(i_d, i_q);
        const double vd = loss.R() * i_d - lim.omega * f.psi_q, vq = loss.R() * i_q + lim.omega * f.psi_d;
        ok = vd * vd + vq * vq <= V2;
        const double T_e = kT * (f.psi_d * i_q - f.psi_q * i_d);
        return s * (T_e - loss.drag(loss.iron().power(kP, loss.w_m(), f.psi_d, f.psi_q)));
    };
    auto on_circle = [&](double a) {
        bool ok;
        const double H = h(lim.I_max * std::cos(a), lim.I_max * std::sin(a), ok);
        return ok ? H : -kInf;
    };
    // every crossing of the voltage limit on the ray within I_max (the origin may be outside it)
    auto on_voltage_limit = [&](double a) {
        const double c = std::cos(a), sn = std::sin(a);
        constexpr int n_r = 200;
        double H_best = -kInf;
        bool ok0;
        h(0.0, 0.0, ok0);
        for (int k = 1; k <= n_r; ++k) {
            double lo = lim.I_max * (k - 1) / n_r, hi = lim.I_max * k / n_r;
            bool ok1;
            h(hi * c, hi * sn, ok1);
            if (ok1 != ok0) {
                for (int it = 0; it < 60; ++it) {
                    const double m = 0.5 * (lo + hi);
                    bool ok;
                    h(m * c, m * sn, ok);
                    (ok == ok0 ? lo : hi) = m;
                }
                bool ok;
                const double r = ok0 ? lo : hi, H = h(r * c, r * sn, ok);
                if (ok) H_best = std::max(H_best, H);
            }
            ok0 = ok1;
        }
        return H_best;
    };
    double best = -kInf;
    for (const auto& along :
         {std::function<double(double)>(on_circle), std::function<double(double)>(on_voltage_limit)}) {
        double a_best = 0.0, H_best = -kInf;
        for (int j = 0; j < n; ++j) {
            const double a = 2.0 * kPi * j / n, H = along(a);
            if (H > H_best) H_best = H, a_best = a;
        }
        double lo = a_best - 2.0 * kPi / n, hi = a_best + 2.0 * kPi / n;
        for (int it = 0; it < 100; ++it) {
            const double m1 = lo + 0.381966 * (hi - lo), m2 = hi - 0.381966 * (hi - lo);
            const double H1 = along(m1), H2 = along(m2);
            H_best = std::max({H_best, H1, H2});
            (H1 > H2 ? hi : lo) = H1 > H2 ? m2 : m1;
        }
        best = std::max(best, H_best);
    }
    for (int k = 1; k < 200; ++k)
        for (int j = 0; j < 1000; ++j) {
            const double r = lim.I_max * k / 200, a = 2.0 * kPi * j / 1000;
            bool ok;
            const double H = h(r * std::cos(a), r * std::sin(a), ok);
            if (ok) best = std::max(best, H);
        }
    return best;
}

}  // namespace

TEST(LeastLoss, PriusTorqueMaxIsTheLargestShaftTorque) {
    // The published Prius map (PLECS demo; 4 pole pairs, R_s 0.015 Ohm, I_max 200 A): along the
    // current circle its torque has two maxima 1.5 samples of CurrentCircles apart and within
    // 0.02 % of each other; the iron loss's drag makes the one the least-current solver's T_max
    // does not sit on the largest shaft torque (at 1523 r/min, 473 V, the magnets at 116 C: T_max
    // was 1.4e-4 short). The default motor's iron loss and inverter, scaled by the drive's power.
    const auto map = std::make_shared<const FluxMap>(
        read_flux_map(ipmsm::source_path("scenarios/data/fluxmaps/real/plecs_prius_as_published.csv")));
    constexpr double I_max = 200.0, R_s = 0.015;
    const double scale = I_max * 500.0 / (kIMax * 355.0);
    const IronLossModel iron{kIron.k_h * scale, 2.0, kIron.k_e * scale, std::abs(map->psi_m())};
    InverterParams inverter;
    inverter.I_ref *= I_max / kIMax;
    SaturatedOptimalCurrent em(map, kP);
    LeastLoss ll(map, kP, false);
    int n = 0;
    for (double T_magnet_rise : {0.0, 96.3}) {
        const double shift = map->psi_m() * -0.0012 * T_magnet_rise;
        const MagnetFlux flux(*map, shift);
        for (double rpm : {-4000.0, 800.0, 1523.0, 2500.0, 4000.0}) {
            for (double u_dc : {473.14, 500.0}) {
                for (double s : {1.0, -1.0}) {
                    const double w = rpm * kPi / 30.0;
                    const OperatingLimits lim{kP * w, 0.95 * u_dc / std::sqrt(3.0), I_max};
                    const DriveLoss loss(iron, inverter, kP, w, R_s, u_dc);
                    const CurrentCommand top = em.solve(s * 1e30, lim, R_s, shift, Recursion::optimal);
                    const LeastLossResult r = ll.solve(s * 1e30, lim, flux, loss, top);
                    const double ref = brute_max_shaft_torque(flux, loss, lim, s);
                    SCOPED_TRACE(::testing::Message()
                                 << rpm << " r/min, u_dc " << u_dc << " V, shift " << shift << " Wb, side " << s);
                    EXPECT_NEAR(r.cmd.torque_max, ref, 1e-6 * ref);
                    EXPECT_NEAR(s * r.cmd.torque, r.cmd.torque_max, 1e-9 * ref);
                    ++n;
                }
            }
        }
    }
    EXPECT_EQ(n, 40);
    // Below T_max, where the loss along the curve ripples (the spline over the 10/20 A grid): at
    // 900 r/min, 500 V, 238 N.m two local minima 4.7 A and 0.07 % apart; the least one.
    const MagnetFlux flux(*map, 0.0);
    const double w = 900.0 * kPi / 30.0, T = 238.06927511591843;
    const OperatingLimits lim{kP * w, 0.95 * 500.0 / std::sqrt(3.0), I_max};
    const DriveLoss loss(iron, inverter, kP, w, R_s, 500.0);
    const CurrentCommand top = em.solve(1e30, lim, R_s, 0.0, Recursion::optimal);
    const CurrentCommand least_current = em.solve(T, lim, R_s, 0.0, Recursion::optimal);
    const CurrentPoint hint{least_current.i_d, least_current.i_q};  // as the controller seeds it
    const LeastLossResult r = ll.solve(T, lim, flux, loss, top, &hint);
    const Brute b = brute_force(flux, loss, lim, T);
    EXPECT_NEAR(r.cmd.torque, T, 1e-9 * T);
    EXPECT_LE(r.loss.total(), b.P * (1 + 1e-6))
        << "brute force at (" << b.i_d << ", " << b.i_q << ") A, command (" << r.cmd.i_d << ", " << r.cmd.i_q << ") A";
}

// The scan below T_max skips the stretches of the current circles whose shaft-torque bounds
// exclude T* (docs/spec/MATH.md, "Least-loss control"). The bounds: every sample's shaft torque,
// computed as the solver computes it, within its stretch's bounds, at magnet shifts of both signs,
// both directions of rotation, iron-loss exponents 2 and 1.6; and not wider than they need be
// (the samples come within 2 % of the bounds' width of each end on some stretch).
TEST(LeastLoss, StretchTorqueBoundsHoldEverySample) {
    const auto map =
        std::make_shared<const FluxMap>(saturating_flux_map(kLd, kLq, kPsiM, 200.0, 0.15, kIMax, 1.3 * kIMax, 53));
    const CurrentCircles C(*map, kIMax);
    const double kT = 1.5 * kP;
    long checked = 0, tight = 0;
    for (double alpha : {2.0, 1.6}) {
        const IronLossModel iron{kIron.k_h, alpha, kIron.k_e, kIron.psi_ref};
        for (double shift : {-0.006, 0.0, 0.004}) {
            for (double w_m : {-900.0, 0.0, 250.0, 1200.0}) {
                const double f = IronLossModel::frequency(kP, w_m);
                for (int k = 1; k <= CurrentCircles::kRadii; ++k) {
                    const LeastLoss::Interval drag_circle = LeastLoss::drag_bounds(C.whole(k), shift, iron, f, w_m);
                    for (int m = 0; m < CurrentCircles::kArcs; ++m) {
                        const CurrentCircles::Arc& A = C.arc(k, m);
                        for (const LeastLoss::Interval& drag :
                             {drag_circle, LeastLoss::drag_bounds(A, shift, iron, f, w_m)}) {
                            const LeastLoss::Interval h = LeastLoss::stretch_torque_bounds(A, kT, shift, drag);
                            double lo = INFINITY, hi = -INFINITY;
                            for (int j = m * CurrentCircles::kArc; j <= (m + 1) * CurrentCircles::kArc; ++j) {
                                const CurrentCircles::Sample& x = C.at(k, j);
                                const double psi_d = x.psi_d + shift;
                                const double P_fe = f > 0.0 ? iron.power_at(f, psi_d * psi_d + x.psi_q * x.psi_q) : 0.0;
                                const double T =
                                    kT * (psi_d * x.i_q - x.psi_q * x.i_d) - (w_m != 0.0 ? P_fe / w_m : 0.0);
                                EXPECT_GE(T, h.lo) << "circle " << k << ", sample " << j;
                                EXPECT_LE(T, h.hi) << "circle " << k << ", sample " << j;
                                lo = std::min(lo, T), hi = std::max(hi, T);
                                ++checked;
                            }
                            tight += lo - h.lo <= 0.02 * (h.hi - h.lo) && h.hi - hi <= 0.02 * (h.hi - h.lo);
                        }
                    }
                }
            }
        }
    }
    EXPECT_EQ(checked, 2L * 3 * 4 * CurrentCircles::kRadii * CurrentCircles::kArcs * 2 * (CurrentCircles::kArc + 1));
    EXPECT_GT(tight, 0);
}

// The scan visits only the stretches whose bounds include T*, the reference scan every one: the
// same crossings, so the same command, bit for bit, on random operating points in four quadrants
// (a saturating map, magnets warm; with and without the least-current hint); and fewer samples.
TEST(LeastLoss, StretchPruningKeepsTheCommandBitForBit) {
    const auto map =
        std::make_shared<const FluxMap>(saturating_flux_map(kLd, kLq, kPsiM, 200.0, 0.15, kIMax, 1.3 * kIMax, 53));
    SaturatedOptimalCurrent em(map, kP);
    LeastLoss fast(map, kP, false), reference(map, kP, false);
    reference.set_reference_scan(true);
    const double shift = -0.004;
    const MagnetFlux flux(*map, shift);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> U(0.0, 1.0);
    long evaluations_fast = 0, evaluations_reference = 0;
    int below_top = 0;
    for (int n = 0; n < 300; ++n) {
        const double w = (U(rng) < 0.5 ? -1 : 1) * 12000.0 * U(rng) * kPi / 30.0, u_dc = 300.0 + 100.0 * U(rng);
        const OperatingLimits lim{kP * w, 0.95 * u_dc / std::sqrt(3.0), kIMax};
        const IronLossModel iron{kIron.k_h, n % 3 == 0 ? 1.7 : 2.0, kIron.k_e, kIron.psi_ref};
        const DriveLoss loss(iron, kInverter, kP, w, kRs, u_dc);
        const double side = U(rng) < 0.5 ? -1.0 : 1.0;
        const CurrentCommand top = em.solve(side * 1e30, lim, kRs, shift, Recursion::optimal);
        const double T = side * top.torque_max * 1.05 * U(rng);
        const CurrentCommand least_current = em.solve(T, lim, kRs, shift, Recursion::optimal);
        const CurrentPoint hint{least_current.i_d, least_current.i_q};
        const CurrentPoint* h = n % 2 ? &hint : nullptr;
        const LeastLossResult a = fast.solve(T, lim, flux, loss, top, h),
                              b = reference.solve(T, lim, flux, loss, top, h);
        SCOPED_TRACE(::testing::Message() << w << " rad/s, T = " << T << " N.m, u_dc = " << u_dc);
        EXPECT_EQ(a.cmd.i_d, b.cmd.i_d);
        EXPECT_EQ(a.cmd.i_q, b.cmd.i_q);
        EXPECT_EQ(a.cmd.torque, b.cmd.torque);
        EXPECT_EQ(a.cmd.torque_max, b.cmd.torque_max);
        EXPECT_EQ(a.cmd.region, b.cmd.region);
        EXPECT_EQ(a.check_passed, b.check_passed);
        EXPECT_EQ(a.searched, b.searched);
        EXPECT_LE(a.evaluations, b.evaluations);
        evaluations_fast += a.evaluations, evaluations_reference += b.evaluations;
        below_top += std::abs(T) < a.cmd.torque_max;
    }
    EXPECT_GT(below_top, 200);
    EXPECT_LT(evaluations_fast, evaluations_reference);
    std::printf("evaluations: %ld pruned, %ld reference scan\n", evaluations_fast, evaluations_reference);
}
