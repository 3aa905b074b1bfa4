#include "thermal/thermal_network.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace ipmsm::thermal {

namespace {
std::string num(double x) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.6g", x);
    return buf;
}
}  // namespace

template <int N, int M>
NetworkPropagator<N, M>::NetworkPropagator(const Vec& capacities) : C_(capacities) {
    for (int i = 0; i < N; ++i)
        if (!(std::isfinite(C_[i]) && C_[i] > 0.0))
            throw std::invalid_argument("thermal network: heat capacity of node " + std::to_string(i) + " is " +
                                        num(C_[i]) + " J/K (must be finite and > 0)");
    d_ = C_.cwiseSqrt().cwiseInverse();
    d_inv_ = C_.cwiseSqrt();
}

template <int N, int M>
void NetworkPropagator<N, M>::set_conductances(const Conductances& g) {
    if (set_ && g == g_) return;  // the decomposition still holds
    for (int i = 0; i < N; ++i) {
        for (int j = 0; j < N; ++j) {
            const double x = g.between(i, j);
            if (!(std::isfinite(x) && x >= 0.0))
                throw std::invalid_argument("thermal network: conductance between nodes " + std::to_string(i) +
                                            " and " + std::to_string(j) + " is " + num(x) +
                                            " W/K (must be finite and >= 0)");
            if (i == j && x != 0.0)
                throw std::invalid_argument("thermal network: a node's conductance to itself must be 0");
            if (x != g.between(j, i))
                throw std::invalid_argument("thermal network: conductances between nodes " + std::to_string(i) +
                                            " and " + std::to_string(j) + " differ by direction");
        }
        for (int k = 0; k < M; ++k) {
            const double x = g.boundary(i, k);
            if (!(std::isfinite(x) && x >= 0.0))
                throw std::invalid_argument("thermal network: conductance from node " + std::to_string(i) +
                                            " to boundary " + std::to_string(k) + " is " + num(x) +
                                            " W/K (must be finite and >= 0)");
        }
    }
    K_ = -g.between;
    K_.diagonal() = g.between.rowwise().sum() + g.boundary.rowwise().sum();
    const Eigen::Matrix<double, N, N> S = d_.asDiagonal() * K_ * d_.asDiagonal();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> eig(S);
    // A node (group) without a path to a boundary has a zero rate: no steady state.
    if (eig.info() != Eigen::Success || !(eig.eigenvalues()[0] > 1e-12 * eig.eigenvalues()[N - 1]))
        throw std::invalid_argument("thermal network: a node has no path to a boundary (no steady state)");
    V_ = eig.eigenvectors();
    lambda_ = eig.eigenvalues();
    g_ = g;
    set_ = true;
}

template <int N, int M>
typename NetworkPropagator<N, M>::Vec NetworkPropagator<N, M>::steady_state(const Vec& P, const Bnd& theta_b) const {
    if (!set_) throw std::logic_error("thermal network: conductances not set");
    // K^-1 = D V diag(1/lambda) V^T D
    const Vec q = P + g_.boundary * theta_b;
    return d_.asDiagonal() * (V_ * (lambda_.cwiseInverse().asDiagonal() * (V_.transpose() * d_.asDiagonal() * q)));
}

template <int N, int M>
StepHeat<N, M> NetworkPropagator<N, M>::step(const Vec& theta0, const Vec& P, const Bnd& theta_b, double h) const {
    if (!(std::isfinite(h) && h >= 0.0))
        throw std::invalid_argument("thermal network: step length " + num(h) + " s (must be finite and >= 0)");
    const Vec ss = steady_state(P, theta_b);
    const Vec z = V_.transpose() * (d_inv_.asDiagonal() * (theta0 - ss));  // modal coordinates
    Vec decay, integral;  // exp(-lambda h), (1 - exp(-lambda h)) / lambda
    for (int i = 0; i < N; ++i) {
        const double e = std::expm1(-lambda_[i] * h);
        decay[i] = 1.0 + e;
        integral[i] = -e / lambda_[i];
    }
    StepHeat<N, M> out;
    out.theta = ss + d_.asDiagonal() * (V_ * decay.cwiseProduct(z));
    // int_0^h theta dt minus the steady state's share, then each boundary's int (theta - theta_b)
    const Vec transient = d_.asDiagonal() * (V_ * integral.cwiseProduct(z));
    for (int k = 0; k < M; ++k)
        out.boundary[k] = g_.boundary.col(k).dot((ss.array() - theta_b[k]).matrix() * h + transient);
    return out;
}

template class NetworkPropagator<4, 2>;

}  // namespace ipmsm::thermal
