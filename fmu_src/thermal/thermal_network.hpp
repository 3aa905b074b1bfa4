// A linear lumped-parameter thermal network (LPTN) and its exact step.
//
// N nodes with heat capacities C_i (J/K), conductances g_ij between nodes and g_ik from node i to
// M boundaries held at temperatures theta_b,k (coolant, ambient air, ...), and heat sources P_i:
//
//     C dtheta/dt = P + G_b theta_b - K theta,   K = L(g_ij) + diag(sum_k g_ik)
//
// with L the network's Laplacian (symmetric, rows summing to zero). K is symmetric positive
// definite when every node reaches a boundary, so the system is stable and has one steady state
// theta_ss = K^-1 (P + G_b theta_b).
//
// Over a step of length h with constant conductances, boundary temperatures and sources the
// solution is exact, by one of two evaluations of the same closed form (A = -C^-1 K, f0 the
// temperatures' rate at the step's start, C^-1 (P + G_b theta_b - K theta0)):
//
//   short steps, h ||A||_inf <= 1/2: the series of the matrix exponential's phi functions,
//     theta(h) = theta0 + sum_k (Ah)^k f0 h / (k+1)!,  int_0^h theta dt = theta0 h + h sum_k (Ah)^k f0 h / (k+2)!,
//     summed until a term no longer changes the sum in double precision (at most ~15 terms; a few
//     4x4 matrix-vector products: a communication step is far shorter than the fastest time constant);
//   longer steps: the eigen-decomposition of the symmetric S = D K D = V diag(lambda) V^T,
//     D = diag(C^-1/2) (lambda > 0, V orthogonal), exp(At) = D V diag(exp(-lambda t)) V^T D^-1:
//     theta(t) = theta_ss + D V diag(exp(-lambda t)) V^T D^-1 (theta0 - theta_ss),
//     int_0^h theta dt = theta_ss h + D V diag(-expm1(-lambda h) / lambda) V^T D^-1 (theta0 - theta_ss),
//     computed once per set of conductances and kept while they are unchanged.
//
// The integral gives the heat into each boundary over the step, sum_i g_ik (int theta_i - theta_b,k h),
// computed from the temperatures and not from the balance, so that the balance
// sum P h = sum C (theta(h) - theta0) + heat into the boundaries is a check, not an identity.
// A caller whose sources vary within a step passes their means (exact integrals / h): the heat
// put in is then exact, the temperatures within the step follow the mean (docs/thermal.md).
#pragma once

#include <Eigen/Dense>

namespace ipmsm::thermal {

template <int N, int M>
struct NetworkConductances {
    Eigen::Matrix<double, N, N> between = Eigen::Matrix<double, N, N>::Zero();   // W/K, symmetric, zero diagonal
    Eigen::Matrix<double, N, M> boundary = Eigen::Matrix<double, N, M>::Zero();  // W/K, node i to boundary k
    bool operator==(const NetworkConductances& o) const { return between == o.between && boundary == o.boundary; }
};

// The heat a step moved (J) and its end temperatures (K).
template <int N, int M>
struct StepHeat {
    Eigen::Matrix<double, N, 1> theta;     // K, at the step's end
    Eigen::Matrix<double, M, 1> boundary;  // J into each boundary over the step
};

// The exact propagator of one network (capacities fixed; conductances set per step).
template <int N, int M>
class NetworkPropagator {
public:
    using Vec = Eigen::Matrix<double, N, 1>;
    using Bnd = Eigen::Matrix<double, M, 1>;
    using Conductances = NetworkConductances<N, M>;

    explicit NetworkPropagator(const Vec& capacities);  // J/K, each > 0 and finite (else throws)

    // Sets the conductances (W/K, each >= 0 and finite, `between` symmetric; every node must reach
    // a boundary): throws std::invalid_argument naming what is wrong.
    void set_conductances(const Conductances& g);
    const Conductances& conductances() const { return g_; }
    const Vec& capacities() const { return C_; }

    // theta_ss for sources P (W) and boundary temperatures theta_b (K).
    Vec steady_state(const Vec& P, const Bnd& theta_b) const;
    // One exact step of length h >= 0 (s) from theta0 (K).
    StepHeat<N, M> step(const Vec& theta0, const Vec& P, const Bnd& theta_b, double h) const;
    // The decay rates lambda (1/s, ascending): the time constants are 1 / lambda.
    const Vec& rates() const;
    // The longest step the series takes (s): 1 / (2 ||C^-1 K||_inf).
    double series_step_max() const { return 0.5 / A_norm_; }

private:
    void decompose() const;  // V_, lambda_ for the present conductances, once
    StepHeat<N, M> series_step(const Vec& theta0, const Vec& P, const Bnd& theta_b, double h) const;
    StepHeat<N, M> modal_step(const Vec& theta0, const Vec& P, const Bnd& theta_b, double h) const;

    Vec C_, d_, d_inv_;  // C, C^-1/2, C^1/2
    Conductances g_;
    bool set_ = false;
    Eigen::Matrix<double, N, N> K_, A_;  // K, -C^-1 K
    double A_norm_ = 0.0;                // ||A||_inf
    mutable bool decomposed_ = false;
    mutable Eigen::Matrix<double, N, N> V_;
    mutable Vec lambda_;
};

// Instantiated in thermal_network.cpp for the networks the project uses.
extern template class NetworkPropagator<4, 2>;

}  // namespace ipmsm::thermal
