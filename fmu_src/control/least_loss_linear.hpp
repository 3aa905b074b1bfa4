// Least loss on a linear machine (psi_d = psi_m + L_d i_d, psi_q = L_q i_q) with an iron loss
// quadratic in flux (alpha = 2): the seed's method carried to the problem the seed left open
// (docs/spec/MATH.md, "Least-loss control on a linear machine: a quartic").
//
// With the inverter's term b |i| majorised at a radius rho, b |i| <= b |i|^2 / (2 rho) + b rho / 2
// (equal at |i| = rho), the loss on the shaft-torque curve is a quadratic form
//     Q = A |i|^2 + e K |psi|^2,   A = a + b / (2 rho),   K = (k_h f + k_e f^2) / psi_ref^2
// and the curve h(i) = 1.5 p (psi_m i_q + (L_d - L_q) i_d i_q) - (K / w_m) |psi|^2 = T* a conic.
// Lagrange, grad Q = lambda grad h, is linear in i for each lambda: i(lambda) = N(lambda) / D(lambda)
// with N, D quadratic in lambda, and h(i(lambda)) D^2 = T* D^2 is a quartic in lambda, solved by
// Ferrari (numerics/quartic.hpp). Of its real roots the point of least loss is the step's exact
// minimiser; rho <- |i| (majorise-minimise: every step exact, the loss falls at every step, its
// fixed point is the stationary point of the full loss a|i|^2 + b|i| + e K |psi|^2).
#pragma once

namespace ipmsm::least_loss_linear {

struct Machine {
    double psi_m, L_d, L_q;  // Wb, H, H
    double kT;               // 1.5 p
};

// The loss on the curve, J = a |i|^2 + b |i| + e K |psi|^2, and the drag coefficient kappa = K / w_m.
struct Loss {
    double a, b, e, K, kappa;
};

struct Result {
    double i_d = 0, i_q = 0;
    double J = 0;        // W, the loss above at the result
    int iterations = 0;  // majorise-minimise steps (one quartic each)
    bool found = false;
};

// The quartic of one majorise-minimise step at radius rho: coefficients c[0] lambda^4 + ... + c[4].
void step_quartic(const Machine& m, const Loss& l, double T, double rho, double (&c)[5]);

// The point i(lambda) of a root (false where D(lambda) = 0).
bool point_of(const Machine& m, const Loss& l, double rho, double lambda, double& i_d, double& i_q);

// The unconstrained least loss for the shaft torque T (no voltage or current limit), from rho0 > 0.
Result solve(const Machine& m, const Loss& l, double T, double rho0, int max_iterations = 200, double tol = 1e-13);

}  // namespace ipmsm::least_loss_linear
