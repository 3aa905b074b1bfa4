// The machine's thermal network (fmu_src/thermal/): the exact step against independent solutions
// (an LU solve of the conductance matrix, a fine classical Runge-Kutta integration), the heat
// balance, the semigroup property, and bad parameters refused.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "thermal/motor_thermal.hpp"

using namespace ipmsm::thermal;

namespace {

constexpr double kRpm = 2.0 * 3.14159265358979323846 / 60.0;  // rad/s per r/min

// K = L + diag(boundary row sums), built here from the conductances directly (not the propagator's).
Eigen::Matrix4d conductance_matrix(const NetworkConductances<kNodes, kBoundaries>& g) {
    Eigen::Matrix4d K = -g.between;
    for (int i = 0; i < kNodes; ++i) K(i, i) = g.between.row(i).sum() + g.boundary.row(i).sum();
    return K;
}

// Classical RK4 with n sub-steps of C dtheta/dt = P + G_b theta_b - K theta.
NodeVector rk4(const NodeVector& C, const Eigen::Matrix4d& K, const NodeVector& q, NodeVector theta, double h, int n) {
    auto f = [&](const NodeVector& x) -> NodeVector { return (q - K * x).cwiseQuotient(C); };
    const double dt = h / n;
    for (int s = 0; s < n; ++s) {
        const NodeVector k1 = f(theta), k2 = f(theta + 0.5 * dt * k1), k3 = f(theta + 0.5 * dt * k2),
                         k4 = f(theta + dt * k3);
        theta += dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4);
    }
    return theta;
}

}  // namespace

TEST(ThermalNetwork, SteadyStateIsTheConductanceMatrixSolution) {
    const LptnParams p;
    for (double rpm : {0.0, 1500.0, 6000.0}) {
        MotorPropagator prop(capacities(p));
        const auto g = conductances(p, rpm * kRpm, 338.15);
        prop.set_conductances(g);
        const NodeVector P = node_losses(p, 1200.0, 800.0, rpm * kRpm, 150.0);
        BoundaryVector tb(338.15, 298.15);
        const NodeVector lu = conductance_matrix(g).fullPivLu().solve(P + g.boundary * tb);
        EXPECT_LT((prop.steady_state(P, tb) - lu).cwiseAbs().maxCoeff(), 1e-9) << rpm;
        // a step of 100 slowest time constants lands on it
        const NodeVector theta0 = NodeVector::Constant(250.0);
        const auto far = prop.step(theta0, P, tb, 100.0 / prop.rates()[0]);
        EXPECT_LT((far.theta - lu).cwiseAbs().maxCoeff(), 1e-9) << rpm;
    }
}

TEST(ThermalNetwork, StepEqualsAFineRungeKuttaIntegration) {
    const LptnParams p;
    MotorPropagator prop(capacities(p));
    const auto g = conductances(p, 3000.0 * kRpm, 318.15);
    prop.set_conductances(g);
    const NodeVector P = node_losses(p, 3000.0, 1500.0, 3000.0 * kRpm, 200.0);
    const BoundaryVector tb(318.15, 303.15);
    NodeVector theta0;
    theta0 << 330.0, 335.0, 360.0, 340.0;
    for (double h : {1e-4, 1.0, 60.0}) {
        const NodeVector ref = rk4(capacities(p), conductance_matrix(g), P + g.boundary * tb, theta0, h, 20000);
        EXPECT_LT((prop.step(theta0, P, tb, h).theta - ref).cwiseAbs().maxCoeff(), 1e-9) << h;
    }
}

TEST(ThermalNetwork, StepsComposeAcrossBothEvaluations) {
    // short steps sum the series, long ones use the eigen-decomposition: the same flow
    const LptnParams p;
    MotorPropagator prop(capacities(p));
    prop.set_conductances(conductances(p, 800.0 * kRpm, 293.15));
    const NodeVector P = node_losses(p, 2000.0, 300.0, 800.0 * kRpm, 250.0);
    const BoundaryVector tb(293.15, 293.15);
    const NodeVector theta0 = NodeVector::Constant(293.15);
    const double h = 0.9 * prop.series_step_max();        // series
    const auto once = prop.step(theta0, P, tb, 2.0 * h);  // eigen-decomposition
    const auto first = prop.step(theta0, P, tb, h);
    const auto second = prop.step(first.theta, P, tb, h);
    EXPECT_LT((once.theta - second.theta).cwiseAbs().maxCoeff(), 1e-10);
    for (int k : {coolant, ambient})
        EXPECT_NEAR(once.boundary[k], first.boundary[k] + second.boundary[k], 1e-10 * std::abs(once.boundary[k]));
    // 1000 short steps against one long one
    NodeVector theta = theta0;
    double to_coolant = 0.0;
    for (int k = 0; k < 1000; ++k) {
        const auto s = prop.step(theta, P, tb, 0.01);
        theta = s.theta, to_coolant += s.boundary[coolant];
    }
    const auto ten = prop.step(theta0, P, tb, 10.0);
    EXPECT_LT((ten.theta - theta).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_NEAR(ten.boundary[coolant], to_coolant, 1e-9 * std::abs(to_coolant));
}

TEST(ThermalNetwork, HeatBalanceOverARunWithChangingLossesAndSpeed) {
    const LptnParams p;
    MotorThermal net(p, 293.15);
    StepConditions at;
    double t = 0.0;
    const double h = 0.01;
    for (int k = 0; k < 200000; ++k, t += h) {  // 2000 s
        at.w_m = 6000.0 * kRpm * (0.5 + 0.5 * std::sin(t / 50.0));
        at.I_rms = 200.0 * std::abs(std::sin(t / 13.0));
        at.T_coolant = 313.15 + 10.0 * std::sin(t / 300.0);
        at.T_ambient = 298.15;
        const double P_cu = 3.0 * 0.012 * at.I_rms * at.I_rms, P_fe = 1500.0 * std::abs(at.w_m) / (6000.0 * kRpm);
        net.advance(h, P_cu * h, P_fe * h, at);
    }
    const double residual = net.E_loss() - net.E_stored() - net.E_coolant() - net.E_ambient();
    EXPECT_GT(net.E_loss(), 1e6);
    EXPECT_LT(std::abs(residual), 1e-6 * net.E_loss()) << residual;
    EXPECT_GT(net.theta(winding), 293.15 + 10.0);
}

TEST(ThermalNetwork, FitsHeldAtTheirRange) {
    const LptnParams p;
    EXPECT_EQ(conductances(p, 12000.0 * kRpm, 293.15), conductances(p, 6000.0 * kRpm, 293.15));
    EXPECT_EQ(conductances(p, -3000.0 * kRpm, 293.15), conductances(p, 3000.0 * kRpm, 293.15));
    EXPECT_EQ(conductances(p, 100.0, 233.15), conductances(p, 100.0, 273.15));  // -40 degC held at 0 degC
    for (double rpm : {0.0, 3000.0, 12000.0})
        for (double I : {0.0, 100.0, 400.0}) {
            const IronLossSplit s = iron_loss_split(p, rpm * kRpm, I);
            EXPECT_NEAR(s.stator_yoke + s.stator_tooth + s.magnet, 1.0, 1e-15);
            EXPECT_GE(s.magnet, 0.0);
            EXPECT_GE(s.stator_tooth, 0.0);
        }
}

TEST(ThermalNetwork, BadParametersAreRefused) {
    LptnParams p;
    p.C_winding = -1.0;
    EXPECT_THROW(MotorThermal(p, 293.15), std::invalid_argument);
    p = LptnParams();
    p.R_magnet_coolant_nc = -2.0;  // the bilinear fit negative at a corner
    EXPECT_THROW(MotorThermal(p, 293.15), std::invalid_argument);
    // Time constants spanning more decades than the exact step resolves: refused naming the
    // capacities (a winding of 1e-300 J/K ran to 0 K in one step before); a winding a million
    // times lighter than the identified network's passes.
    p = LptnParams();
    p.C_winding = 1e-300;
    try {
        MotorThermal bad(p, 293.15);
        ADD_FAILURE() << "a winding of 1e-300 J/K was accepted";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("C_winding = 1e-300 J/K"), std::string::npos) << e.what();
    }
    p = LptnParams();
    p.C_winding *= 1e-6;
    EXPECT_NO_THROW(MotorThermal(p, 293.15));
    p = LptnParams();
    MotorThermal net(p, 293.15);
    EXPECT_THROW(net.advance(0.0, 1.0, 0.0, StepConditions()), std::invalid_argument);
    EXPECT_THROW(net.advance(0.1, std::nan(""), 0.0, StepConditions()), std::invalid_argument);
    // an isolated node has no steady state
    MotorPropagator prop(capacities(p));
    auto g = conductances(p, 0.0, 293.15);
    g.between.row(magnet).setZero(), g.between.col(magnet).setZero(), g.boundary.row(magnet).setZero();
    EXPECT_THROW(prop.set_conductances(g), std::invalid_argument);
    g = conductances(p, 0.0, 293.15);
    g.between(0, 1) = 5.0;  // asymmetric
    EXPECT_THROW(prop.set_conductances(g), std::invalid_argument);
}
