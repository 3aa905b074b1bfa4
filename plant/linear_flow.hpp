// The exact flow of a linear, constant-coefficient 2 x 2 system, in closed form:
//
//     y' = A (y - y0) + f0,  y(0) = y0   =>   y(tau) = y0 + P(tau) f0,
//     P(tau) = int_0^tau exp(sigma A) d sigma = tau phi_1(tau A),   and exp(tau A), exp(-tau A).
//
// The plant linearises its dq equations at the start of each communication step and lets CVODE
// integrate only what the linearisation misses (plant/cvode_integrator.hpp); the dq frame's
// rotation omega J, the fast part (omega tau up to several radians per step), is then exact.
//
// exp(tau A) for 2 x 2 A (Cayley-Hamilton): with s = tr A / 2, B = A - s I, B^2 = q I,
// q = ((a - d) / 2)^2 + b c:  exp(tau A) = e^(s tau) (C I + S B),  C = cosh(sqrt(q) tau),
// S = sinh(sqrt(q) tau) / sqrt(q)  (cos, sin / sqrt(-q) for q < 0; their Taylor series for
// |q| tau^2 small, where the closed forms lose digits); the inverse is e^(-s tau) (C I - S B)
// since C^2 - q S^2 = 1.  P(tau): A^-1 (exp(tau A) - I) when |tau A| > 1 (no cancellation
// there), else the series tau sum_k (tau A)^k / (k + 1)!, which is exact to rounding for a
// small or singular A (standstill without resistance: A = 0, P = tau I).
#pragma once

#include <cmath>

namespace ipmsm {

class LinearFlow {
public:
    LinearFlow() = default;
    // A row-major: A[0] = a_11, A[1] = a_12, A[2] = a_21, A[3] = a_22.
    explicit LinearFlow(const double* A) {
        for (int k = 0; k < 4; ++k) A_[k] = A[k];
        s_ = 0.5 * (A[0] + A[3]);
        B_[0] = A[0] - s_;
        B_[1] = A[1];
        B_[2] = A[2];
        B_[3] = A[3] - s_;
        q_ = B_[0] * B_[0] + A[1] * A[2];
        det_ = A[0] * A[3] - A[1] * A[2];
        norm_ = std::fmax(std::fabs(A[0]) + std::fabs(A[1]), std::fabs(A[2]) + std::fabs(A[3]));
    }

    // The fastest decay rate, -min Re(eigenvalue of A), 1/s (negative if every mode grows).
    double max_decay() const { return -(s_ - (q_ > 0 ? std::sqrt(q_) : 0.0)); }

    // exp(tau A) and exp(-tau A), row-major.
    void exp(double tau, double* E, double* E_inv) const {
        double C, S;
        cosh_sinh(tau, C, S);
        const double e = std::exp(s_ * tau), ei = 1.0 / e;
        E[0] = e * (C + S * B_[0]);
        E[1] = e * (S * B_[1]);
        E[2] = e * (S * B_[2]);
        E[3] = e * (C + S * B_[3]);
        E_inv[0] = ei * (C - S * B_[0]);
        E_inv[1] = -ei * (S * B_[1]);
        E_inv[2] = -ei * (S * B_[2]);
        E_inv[3] = ei * (C - S * B_[3]);
    }

    // P(tau) = int_0^tau exp(sigma A) d sigma, row-major; E = exp(tau A) from exp().
    void integral(double tau, const double* E, double* P) const {
        const double n = norm_ * std::fabs(tau);
        if (n > 1.0 && std::fabs(det_) * tau * tau > 1e-3 * n * n) {
            // A^-1 (E - I); the determinant guard keeps A^-1 well conditioned relative to |A|.
            const double m0 = E[0] - 1.0, m1 = E[1], m2 = E[2], m3 = E[3] - 1.0;
            const double id = 1.0 / det_;
            P[0] = id * (A_[3] * m0 - A_[1] * m2);
            P[1] = id * (A_[3] * m1 - A_[1] * m3);
            P[2] = id * (-A_[2] * m0 + A_[0] * m2);
            P[3] = id * (-A_[2] * m1 + A_[0] * m3);
            return;
        }
        // Horner: tau (I + M/2 (I + M/3 (I + ... (I + M/(K+1))))), M = tau A; K terms until
        // n^K / (K + 1)! is below rounding (n <= 1 here unless A is near-singular and large,
        // where the series still converges, with at most a few digits of cancellation).
        int K = 1;
        for (double term = n; term > 1e-17 && K < 60; ++K) term *= n / (K + 1);
        const double M[4] = {tau * A_[0], tau * A_[1], tau * A_[2], tau * A_[3]};
        double R[4] = {1, 0, 0, 1};
        for (int k = K; k >= 1; --k) {
            const double c = 1.0 / (k + 1);
            const double r0 = c * (M[0] * R[0] + M[1] * R[2]), r1 = c * (M[0] * R[1] + M[1] * R[3]);
            const double r2 = c * (M[2] * R[0] + M[3] * R[2]), r3 = c * (M[2] * R[1] + M[3] * R[3]);
            R[0] = 1.0 + r0;
            R[1] = r1;
            R[2] = r2;
            R[3] = 1.0 + r3;
        }
        for (int k = 0; k < 4; ++k) P[k] = tau * R[k];
    }

private:
    void cosh_sinh(double tau, double& C, double& S) const {
        const double x = q_ * tau * tau;
        if (std::fabs(x) < 1e-2) {  // truncation below x^5 / 3.6e6 < 3e-17
            C = 1.0 + x * (1.0 / 2 + x * (1.0 / 24 + x * (1.0 / 720 + x * (1.0 / 40320))));
            S = tau * (1.0 + x * (1.0 / 6 + x * (1.0 / 120 + x * (1.0 / 5040 + x * (1.0 / 362880)))));
        } else if (q_ > 0) {
            const double r = std::sqrt(q_);
            C = std::cosh(r * tau);
            S = std::sinh(r * tau) / r;
        } else {
            const double v = std::sqrt(-q_);
            C = std::cos(v * tau);
            S = std::sin(v * tau) / v;
        }
    }

    double A_[4] = {0, 0, 0, 0}, B_[4] = {0, 0, 0, 0};
    double s_ = 0, q_ = 0, det_ = 0, norm_ = 0;
};

}  // namespace ipmsm
