// The machine's lumped-parameter thermal network: four nodes (stator yoke, stator tooth, winding,
// magnet/rotor) between two boundaries (coolant, ambient air), Wallscheid and Boecker's low-order
// LPTN of an automotive traction PMSM with its speed- and coolant-dependent resistances:
//
//   O. Wallscheid, J. Boecker, "Global identification of a low-order lumped-parameter thermal
//   network for permanent magnet synchronous motors", IEEE Trans. Energy Convers. 31(1),
//   354-365, 2016, doi 10.1109/TEC.2015.2473673 (the network's structure), and
//   O. Wallscheid, "Ein Beitrag zur thermischen Ausnutzung permanenterregter Synchronmotoren in
//   automobilen Traktionsanwendungen", dissertation, Paderborn University, 2017,
//   https://ris.uni-paderborn.de/record/29616 (the identified values).
//
// The values are read from the authors' group's implementation of that network,
// W. Kirchgaessner, github.com/wkirgsn/thermal-nn, aux/lptn_model.py (commit db107df,
// build_wallscheid_lptn/WallscheidLPTNCell, citing the dissertation) and the same values in
// github.com/wkirgsn/diss-wk, src/mawkutils/topology.py (commit 62d889e, WallscheidLPTN). The 2016
// paper's own table could not be read here; docs/thermal.md lists each value and how it is used.
//
//     yoke ---- R_yoke_winding ---- winding          coolant -- R_coolant_yoke(theta_c) -- yoke
//     yoke ---- R_yoke_tooth ------ tooth            coolant -- R_magnet_coolant(n, theta_c) -- magnet
//     tooth --- R_tooth_winding --- winding          ambient -- R_magnet_ambient(n) -- magnet
//     tooth --- R_tooth_magnet(n) - magnet
//     winding - R_winding_magnet(n) magnet
//
// n = |w_m| / w_m_ref; theta_c the coolant temperature in degC. Losses: the copper loss into the
// winding; the iron loss split k_fe_stator to the stator (k_fe_yoke of it to the yoke, the rest to
// the teeth) and 1 - k_fe_stator to the rotor (magnet node), k_fe_stator a bilinear fit in speed
// and current.
#pragma once

#include <Eigen/Dense>
#include <cmath>

#include "thermal/thermal_network.hpp"

namespace ipmsm::thermal {

enum Node : int { stator_yoke = 0, stator_tooth = 1, winding = 2, magnet = 3 };
enum Boundary : int { coolant = 0, ambient = 1 };
constexpr int kNodes = 4;
constexpr int kBoundaries = 2;
using NodeVector = Eigen::Matrix<double, kNodes, 1>;
using BoundaryVector = Eigen::Matrix<double, kBoundaries, 1>;
using MotorPropagator = NetworkPropagator<kNodes, kBoundaries>;

// R(n) = a exp(-n / b) + c (K/W): heat transfer across the air gap and in the end space improves
// with the rotor's speed (the source's exponential fit)
inline double speed_resistance(double a, double b, double c, double n) { return a * std::exp(-n / b) + c; }

struct LptnParams {
    // heat capacities, J/K (source: caps0..caps3 in the order pm, stator_yoke, stator_tooth, stator_winding)
    double C_stator_yoke = 6.5093e3;
    double C_stator_tooth = 0.437127e3;
    double C_winding = 3.5105e3;
    double C_magnet = 1.0666e4;
    // constant resistances, K/W (source: const_Rs_sy_sw, const_Rs_sy_st, const_Rs_sw_st)
    double R_yoke_winding = 0.0375;
    double R_yoke_tooth = 0.0707;
    double R_tooth_winding = 0.0899;
    // coolant to yoke, K/W: R_coolant_yoke (1 + k_coolant_yoke (theta_c - 20 degC))
    // (source: lin_Rs_bias, lin_Rs_slope): the water jacket's convection improves as the coolant warms
    double R_coolant_yoke = 18e-3;
    double k_coolant_yoke = -54e-4;  // 1/K
    // speed-dependent resistances a exp(-n / b) + c, a and c in K/W
    // (source: exp_Rs_magn0..2 = a, exp_Rs_b0..2 = b, exp_Rs_a0..2 = c)
    double R_tooth_magnet_a = 1.7275, R_tooth_magnet_b = 0.1573, R_tooth_magnet_c = 0.3039;
    double R_winding_magnet_a = 0.8486, R_winding_magnet_b = 0.1428, R_winding_magnet_c = 0.2319;
    double R_magnet_ambient_a = 0.6349, R_magnet_ambient_b = 0.1184, R_magnet_ambient_c = 0.1205;
    // magnet (rotor) to coolant through shaft and bearings, K/W, bilinear in n and c = theta_c / 100 degC:
    // r0 + r_n n + r_c c + r_nc n c (source: bipoly_Rs_magn, bipoly_Rs_a, bipoly_Rs_b, bipoly_Rs_c)
    double R_magnet_coolant_0 = 0.3528;
    double R_magnet_coolant_n = -0.2484;
    double R_magnet_coolant_c = 0.0276;
    double R_magnet_coolant_nc = 0.3331;
    // iron-loss split (source: ploss_k_1_0..3, ploss_k_2): the stator's share
    // k_fe_stator = clamp(k_fe_stator_0 + k_fe_stator_n n + k_fe_stator_i i + k_fe_stator_ni n i, 0, 1),
    // i = I_rms / I_rms_ref; the yoke's share of the stator's k_fe_yoke
    double k_fe_stator_0 = 0.5441;
    double k_fe_stator_n = 78e-4;
    double k_fe_stator_i = 0.0352;
    double k_fe_stator_ni = -0.7438;
    double k_fe_yoke = 0.8655;
    // normalisations of the fits (source: motor_speed / 6000 (r/min), current / 256 (A, RMS))
    double w_m_ref = 6000.0 * 2.0 * 3.14159265358979323846 / 60.0;  // rad/s (mechanical)
    double I_rms_ref = 256.0;                                       // A, RMS phase current
};

// n = |w_m| / w_m_ref, i = I_rms / I_rms_ref and c = theta_c / 100 degC are each held within [0, 1]:
// the fits are not extrapolated (beyond n = 1 the bilinear magnet-coolant resistance falls to zero
// and below at cold coolant; docs/thermal.md).
double normalised_speed(const LptnParams& p, double w_m);

NodeVector capacities(const LptnParams& p);
// The conductances (W/K) at mechanical speed w_m (rad/s) and coolant temperature T_coolant (K).
NetworkConductances<kNodes, kBoundaries> conductances(const LptnParams& p, double w_m, double T_coolant);

// Shares of the iron loss (summing to 1) at speed w_m (rad/s) and RMS phase current I_rms (A).
struct IronLossSplit {
    double stator_yoke, stator_tooth, magnet;
};
IronLossSplit iron_loss_split(const LptnParams& p, double w_m, double I_rms);

// The node sources (W): copper loss into the winding, iron loss split as above.
NodeVector node_losses(const LptnParams& p, double P_cu, double P_fe, double w_m, double I_rms);

// Checks the parameters (throws std::invalid_argument naming the first bad one): capacities and
// resistances finite and > 0 over the fits' whole range, shares within [0, 1], and time constants
// spanning no more than the exact step resolves over that range.
void validate(const LptnParams& p);

}  // namespace ipmsm::thermal
