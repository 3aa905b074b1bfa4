#include "thermal/thermal_network.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

namespace ipmsm::thermal {

namespace {
std::string num(double x) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.6g", x);
    return buf;
}
constexpr int kSeriesTermsMax = 40;  // h ||A|| <= 1/2: 0.5^k / (k+1)! < 1e-17 |sum| from k = 14 on
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
    if (set_ && g == g_) return;  // K, A and the decomposition still hold
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
    // Every node must reach a boundary (else K is singular: no steady state); grow the set of
    // nodes that do from those with a boundary conductance.
    bool reaches[N];
    for (int i = 0; i < N; ++i) reaches[i] = g.boundary.row(i).sum() > 0.0;
    for (int pass = 0; pass < N; ++pass)
        for (int i = 0; i < N; ++i)
            for (int j = 0; j < N; ++j)
                if (reaches[j] && g.between(i, j) > 0.0) reaches[i] = true;
    for (int i = 0; i < N; ++i)
        if (!reaches[i])
            throw std::invalid_argument("thermal network: node " + std::to_string(i) +
                                        " has no path to a boundary (no steady state)");
    K_ = -g.between;
    K_.diagonal() = g.between.rowwise().sum() + g.boundary.rowwise().sum();
    A_ = -(C_.cwiseInverse().asDiagonal() * K_);
    A_norm_ = A_.cwiseAbs().rowwise().sum().maxCoeff();
    g_ = g;
    set_ = true;
    decomposed_ = false;
}

template <int N, int M>
void NetworkPropagator<N, M>::decompose() const {
    if (!set_) throw std::logic_error("thermal network: conductances not set");
    if (decomposed_) return;
    const Eigen::Matrix<double, N, N> S = d_.asDiagonal() * K_ * d_.asDiagonal();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> eig(S);
    if (eig.info() != Eigen::Success || !(eig.eigenvalues()[0] > 0.0))
        throw std::invalid_argument("thermal network: the conductance matrix is not positive definite");
    V_ = eig.eigenvectors();
    lambda_ = eig.eigenvalues();
    decomposed_ = true;
}

template <int N, int M>
const typename NetworkPropagator<N, M>::Vec& NetworkPropagator<N, M>::rates() const {
    decompose();
    return lambda_;
}

template <int N, int M>
typename NetworkPropagator<N, M>::Vec NetworkPropagator<N, M>::steady_state(const Vec& P, const Bnd& theta_b) const {
    decompose();
    // K^-1 = D V diag(1/lambda) V^T D
    const Vec q = P + g_.boundary * theta_b;
    return d_.asDiagonal() * (V_ * (lambda_.cwiseInverse().asDiagonal() * (V_.transpose() * d_.asDiagonal() * q)));
}

template <int N, int M>
StepHeat<N, M> NetworkPropagator<N, M>::step(const Vec& theta0, const Vec& P, const Bnd& theta_b, double h) const {
    if (!set_) throw std::logic_error("thermal network: conductances not set");
    if (!(std::isfinite(h) && h >= 0.0))
        throw std::invalid_argument("thermal network: step length " + num(h) + " s (must be finite and >= 0)");
    return h * A_norm_ <= 0.5 ? series_step(theta0, P, theta_b, h) : modal_step(theta0, P, theta_b, h);
}

template <int N, int M>
StepHeat<N, M> NetworkPropagator<N, M>::series_step(const Vec& theta0, const Vec& P, const Bnd& theta_b,
                                                    double h) const {
    // u_k = (Ah)^k f0 h; theta(h) - theta0 = sum u_k / (k+1)!, int (theta - theta0) = h sum u_k / (k+2)!
    Vec u = h * ((P + g_.boundary * theta_b - K_ * theta0).cwiseQuotient(C_));
    Vec rise = Vec::Zero(), mean_rise = Vec::Zero();
    double f1 = 1.0, f2 = 2.0;  // (k+1)!, (k+2)!
    for (int k = 0; k < kSeriesTermsMax; ++k) {
        const Vec t1 = u / f1, t2 = u / f2;
        const Vec before = rise, mean_before = mean_rise;
        rise += t1;
        mean_rise += t2;
        if (rise == before && mean_rise == mean_before) break;  // the sums no longer change
        u = h * (A_ * u);
        f1 *= k + 2;
        f2 *= k + 3;
    }
    StepHeat<N, M> out;
    out.theta = theta0 + rise;
    for (int k = 0; k < M; ++k)
        out.boundary[k] = h * g_.boundary.col(k).dot((theta0.array() - theta_b[k]).matrix() + mean_rise);
    return out;
}

template <int N, int M>
StepHeat<N, M> NetworkPropagator<N, M>::modal_step(const Vec& theta0, const Vec& P, const Bnd& theta_b,
                                                   double h) const {
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
