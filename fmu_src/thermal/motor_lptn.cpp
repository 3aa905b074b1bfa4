#include "thermal/motor_lptn.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace ipmsm::thermal {

namespace {
constexpr double kZeroCelsius = 273.15;  // K (BIPM, SI Brochure 9th ed., 2.3.1)
constexpr double kCoolantScale = 100.0;  // degC: c = theta_c / 100 degC (the source's normalisation)
constexpr double kCoolantRef = 20.0;     // degC: R_coolant_yoke's reference temperature (source)

double unit_clamp(double x) { return std::clamp(x, 0.0, 1.0); }
// The exact step (thermal_network.hpp) resolves the slowest mode only while the network's decay
// rates span less than this: the decomposition's eigenvalues carry an absolute rounding error of
// about eps lambda_max (Weyl's inequality, Horn and Johnson, Matrix Analysis, 2nd ed., Thm 4.3.1),
// a relative one of eps lambda_max / lambda_min on the slowest mode: 2e-7 here, within the 1e-6 of
// the heat balance the contract holds the network to.
constexpr double kMaxRateRatio = 1e9;

std::string num(double x) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.6g", x);
    return buf;
}

void require(bool ok, const std::string& what, double value) {
    if (!ok) throw std::invalid_argument("thermal network parameter " + what + " = " + num(value));
}

double coolant_yoke(const LptnParams& p, double c) {
    return p.R_coolant_yoke * (1.0 + p.k_coolant_yoke * (c * kCoolantScale - kCoolantRef));
}

double magnet_coolant(const LptnParams& p, double n, double c) {
    return p.R_magnet_coolant_0 + p.R_magnet_coolant_n * n + p.R_magnet_coolant_c * c + p.R_magnet_coolant_nc * n * c;
}
}  // namespace

double normalised_speed(const LptnParams& p, double w_m) { return unit_clamp(std::abs(w_m) / p.w_m_ref); }

NodeVector capacities(const LptnParams& p) {
    NodeVector C;
    C[stator_yoke] = p.C_stator_yoke;
    C[stator_tooth] = p.C_stator_tooth;
    C[winding] = p.C_winding;
    C[magnet] = p.C_magnet;
    return C;
}

NetworkConductances<kNodes, kBoundaries> conductances(const LptnParams& p, double w_m, double T_coolant) {
    const double n = normalised_speed(p, w_m);
    const double c = unit_clamp((T_coolant - kZeroCelsius) / kCoolantScale);
    NetworkConductances<kNodes, kBoundaries> g;
    auto link = [&g](int i, int j, double R) { g.between(i, j) = g.between(j, i) = 1.0 / R; };
    link(stator_yoke, winding, p.R_yoke_winding);
    link(stator_yoke, stator_tooth, p.R_yoke_tooth);
    link(stator_tooth, winding, p.R_tooth_winding);
    link(stator_tooth, magnet, speed_resistance(p.R_tooth_magnet_a, p.R_tooth_magnet_b, p.R_tooth_magnet_c, n));
    link(winding, magnet, speed_resistance(p.R_winding_magnet_a, p.R_winding_magnet_b, p.R_winding_magnet_c, n));
    g.boundary(stator_yoke, coolant) = 1.0 / coolant_yoke(p, c);
    g.boundary(magnet, coolant) = 1.0 / magnet_coolant(p, n, c);
    g.boundary(magnet, ambient) =
        1.0 / speed_resistance(p.R_magnet_ambient_a, p.R_magnet_ambient_b, p.R_magnet_ambient_c, n);
    return g;
}

IronLossSplit iron_loss_split(const LptnParams& p, double w_m, double I_rms) {
    const double n = normalised_speed(p, w_m);
    const double i = unit_clamp(std::abs(I_rms) / p.I_rms_ref);
    const double k_stator =
        unit_clamp(p.k_fe_stator_0 + p.k_fe_stator_n * n + p.k_fe_stator_i * i + p.k_fe_stator_ni * n * i);
    return {p.k_fe_yoke * k_stator, (1.0 - p.k_fe_yoke) * k_stator, 1.0 - k_stator};
}

NodeVector node_losses(const LptnParams& p, double P_cu, double P_fe, double w_m, double I_rms) {
    const IronLossSplit s = iron_loss_split(p, w_m, I_rms);
    NodeVector P;
    P[stator_yoke] = s.stator_yoke * P_fe;
    P[stator_tooth] = s.stator_tooth * P_fe;
    P[winding] = P_cu;
    P[magnet] = s.magnet * P_fe;
    return P;
}

void validate(const LptnParams& p) {
    auto positive = [](double x) { return std::isfinite(x) && x > 0.0; };
    require(positive(p.C_stator_yoke), "C_stator_yoke (J/K, > 0)", p.C_stator_yoke);
    require(positive(p.C_stator_tooth), "C_stator_tooth (J/K, > 0)", p.C_stator_tooth);
    require(positive(p.C_winding), "C_winding (J/K, > 0)", p.C_winding);
    require(positive(p.C_magnet), "C_magnet (J/K, > 0)", p.C_magnet);
    require(positive(p.R_yoke_winding), "R_yoke_winding (K/W, > 0)", p.R_yoke_winding);
    require(positive(p.R_yoke_tooth), "R_yoke_tooth (K/W, > 0)", p.R_yoke_tooth);
    require(positive(p.R_tooth_winding), "R_tooth_winding (K/W, > 0)", p.R_tooth_winding);
    require(positive(p.w_m_ref), "w_m_ref (rad/s, > 0)", p.w_m_ref);
    require(positive(p.I_rms_ref), "I_rms_ref (A, > 0)", p.I_rms_ref);
    require(std::isfinite(p.k_fe_yoke) && p.k_fe_yoke >= 0.0 && p.k_fe_yoke <= 1.0, "k_fe_yoke (within [0, 1])",
            p.k_fe_yoke);
    for (double k : {p.k_fe_stator_0, p.k_fe_stator_n, p.k_fe_stator_i, p.k_fe_stator_ni, p.k_coolant_yoke,
                     p.R_magnet_coolant_0, p.R_magnet_coolant_n, p.R_magnet_coolant_c, p.R_magnet_coolant_nc})
        require(std::isfinite(k), "of the fits (finite)", k);
    const struct {
        const char* name;
        double a, b, c;
    } speed_dependent[] = {{"R_tooth_magnet", p.R_tooth_magnet_a, p.R_tooth_magnet_b, p.R_tooth_magnet_c},
                           {"R_winding_magnet", p.R_winding_magnet_a, p.R_winding_magnet_b, p.R_winding_magnet_c},
                           {"R_magnet_ambient", p.R_magnet_ambient_a, p.R_magnet_ambient_b, p.R_magnet_ambient_c}};
    for (const auto& r : speed_dependent) {
        require(std::isfinite(r.a) && r.a >= 0.0, std::string(r.name) + "_a (K/W, >= 0)", r.a);
        require(positive(r.b), std::string(r.name) + "_b (> 0)", r.b);
        require(positive(r.c), std::string(r.name) + "_c (K/W, > 0)", r.c);
    }
    // linear and bilinear fits: positive over [0, 1] when positive at the ends / corners
    for (double c : {0.0, 1.0}) {
        require(positive(coolant_yoke(p, c)), "R_coolant_yoke at the coolant's limit (K/W, > 0)", coolant_yoke(p, c));
        for (double n : {0.0, 1.0})
            require(positive(magnet_coolant(p, n, c)), "R_magnet_coolant at a corner of its fit (K/W, > 0)",
                    magnet_coolant(p, n, c));
    }
    // The decay rates' span over the fits' domain. Every rate rises with every conductance (each
    // link adds a positive semidefinite term to K), and each conductance takes its extremes at the
    // fits' corners (monotone in speed, linear or bilinear): the rates of the links' minima and
    // maxima bound them.
    auto lo = conductances(p, 0.0, kZeroCelsius), hi = lo;
    for (double n : {0.0, 1.0})
        for (double c : {0.0, 1.0}) {
            const auto g = conductances(p, n * p.w_m_ref, kZeroCelsius + c * kCoolantScale);
            lo.between = lo.between.cwiseMin(g.between), lo.boundary = lo.boundary.cwiseMin(g.boundary);
            hi.between = hi.between.cwiseMax(g.between), hi.boundary = hi.boundary.cwiseMax(g.boundary);
        }
    MotorPropagator slowest(capacities(p)), fastest(capacities(p));
    slowest.set_conductances(lo);
    fastest.set_conductances(hi);
    const double lambda_min = slowest.rates()[0], lambda_max = fastest.rates()[kNodes - 1];
    if (!(lambda_max <= kMaxRateRatio * lambda_min))
        throw std::invalid_argument(
            "thermal network: its time constants span more than a factor " + num(kMaxRateRatio) + " (the fastest " +
            num(1.0 / lambda_max) +
            " s), more than double precision integrates to 1e-6; a heat capacity or a resistance is off by orders "
            "of magnitude (C_stator_yoke = " +
            num(p.C_stator_yoke) + " J/K, C_stator_tooth = " + num(p.C_stator_tooth) +
            " J/K, C_winding = " + num(p.C_winding) + " J/K, C_magnet = " + num(p.C_magnet) + " J/K)");
}

}  // namespace ipmsm::thermal
