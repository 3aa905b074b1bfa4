#include "control/least_loss_linear.hpp"

#include <cmath>

#include "numerics/quartic.hpp"

namespace ipmsm::least_loss_linear {
namespace {

// Polynomials in lambda, coefficient k of lambda^k, degree <= 4.
struct Poly {
    double c[5] = {0, 0, 0, 0, 0};
};
Poly operator+(const Poly& a, const Poly& b) {
    Poly r;
    for (int k = 0; k < 5; ++k) r.c[k] = a.c[k] + b.c[k];
    return r;
}
Poly operator-(const Poly& a, const Poly& b) {
    Poly r;
    for (int k = 0; k < 5; ++k) r.c[k] = a.c[k] - b.c[k];
    return r;
}
Poly operator*(double s, const Poly& a) {
    Poly r;
    for (int k = 0; k < 5; ++k) r.c[k] = s * a.c[k];
    return r;
}
Poly operator*(const Poly& a, const Poly& b) {  // the product's degree stays <= 4 here
    Poly r;
    for (int i = 0; i < 5; ++i)
        for (int j = 0; i + j < 5; ++j) r.c[i + j] += a.c[i] * b.c[j];
    return r;
}
Poly lin(double c0, double c1) {
    Poly p;
    p.c[0] = c0, p.c[1] = c1;
    return p;
}
double at(const Poly& p, double x) { return (((p.c[4] * x + p.c[3]) * x + p.c[2]) * x + p.c[1]) * x + p.c[0]; }

// grad Q = lambda grad h as M(lambda) i = r(lambda): M = [[m11, off], [off, m22]],
//   m11 = 2A + 2 (eK + lambda kappa) L_d^2,  m22 = 2A + 2 (eK + lambda kappa) L_q^2,  off = -lambda kT (L_d - L_q),
//   r = (-2 (eK + lambda kappa) L_d psi_m, lambda kT psi_m);  i = adj(M) r / det M = N / D.
struct Pencil {
    Poly D, N_d, N_q;
};
Pencil pencil(const Machine& m, const Loss& l, double rho) {
    const double A = l.a + l.b / (2.0 * rho), eK = l.e * l.K, dL = m.L_d - m.L_q;
    const Poly m11 = lin(2.0 * A + 2.0 * eK * m.L_d * m.L_d, 2.0 * l.kappa * m.L_d * m.L_d);
    const Poly m22 = lin(2.0 * A + 2.0 * eK * m.L_q * m.L_q, 2.0 * l.kappa * m.L_q * m.L_q);
    const Poly off = lin(0.0, -m.kT * dL);
    const Poly r_d = lin(-2.0 * eK * m.L_d * m.psi_m, -2.0 * l.kappa * m.L_d * m.psi_m);
    const Poly r_q = lin(0.0, m.kT * m.psi_m);
    return {m11 * m22 - off * off, m22 * r_d - off * r_q, m11 * r_q - off * r_d};
}

}  // namespace

void step_quartic(const Machine& m, const Loss& l, double T, double rho, double (&c)[5]) {
    const Pencil p = pencil(m, l, rho);
    // h D^2 = kT (psi_m N_q D + dL N_d N_q) - kappa ((psi_m D + L_d N_d)^2 + (L_q N_q)^2)
    const Poly psi_d = m.psi_m * p.D + m.L_d * p.N_d, psi_q = m.L_q * p.N_q;
    const Poly q = m.kT * (m.psi_m * (p.N_q * p.D) + (m.L_d - m.L_q) * (p.N_d * p.N_q)) -
                   l.kappa * (psi_d * psi_d + psi_q * psi_q) - T * (p.D * p.D);
    for (int k = 0; k < 5; ++k) c[k] = q.c[4 - k];
}

bool point_of(const Machine& m, const Loss& l, double rho, double lambda, double& i_d, double& i_q) {
    const Pencil p = pencil(m, l, rho);
    const double D = at(p.D, lambda);
    if (!(std::abs(D) > 0.0)) return false;
    i_d = at(p.N_d, lambda) / D;
    i_q = at(p.N_q, lambda) / D;
    return std::isfinite(i_d) && std::isfinite(i_q);
}

Result solve(const Machine& m, const Loss& l, double T, double rho0, int max_iterations, double tol) {
    Result best;
    auto loss = [&](double i_d, double i_q) {
        const double pd = m.psi_m + m.L_d * i_d, pq = m.L_q * i_q, c = i_d * i_d + i_q * i_q;
        return l.a * c + l.b * std::sqrt(c) + l.e * l.K * (pd * pd + pq * pq);
    };
    double rho = rho0;
    for (int k = 1; k <= max_iterations; ++k) {
        double c[5];
        step_quartic(m, l, T, rho, c);
        const RealRoots r = solve_quartic(c[0], c[1], c[2], c[3], c[4]);
        // the step's minimiser: of the stationary points (the real roots), the least of the
        // majorised loss Q (its value at |i| = rho is the full loss, and below it elsewhere)
        const double A = l.a + l.b / (2.0 * rho);
        double Q_best = INFINITY, bd = 0, bq = 0;
        for (int n = 0; n < r.count; ++n) {
            double i_d, i_q;
            if (!point_of(m, l, rho, r.root[n], i_d, i_q)) continue;
            const double pd = m.psi_m + m.L_d * i_d, pq = m.L_q * i_q;
            const double Q = A * (i_d * i_d + i_q * i_q) + l.e * l.K * (pd * pd + pq * pq);
            if (Q < Q_best) Q_best = Q, bd = i_d, bq = i_q;
        }
        if (!(Q_best < INFINITY)) return best;
        best.i_d = bd, best.i_q = bq, best.iterations = k, best.found = true;
        best.J = loss(bd, bq);
        const double next = std::hypot(bd, bq);
        if (!(next > 0.0)) return best;
        const bool done = std::abs(next - rho) <= tol * next;
        rho = next;
        if (done) break;
    }
    return best;
}

}  // namespace ipmsm::least_loss_linear
