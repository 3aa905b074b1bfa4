// The linearised (exponential) step of the plant's integrator (cvode_integrator.hpp): the dq
// equations linearised at the step's start psi0, the linear part's flow exact (linear_flow.hpp),
// and the right-hand side of what it misses, z' = exp(-tau A) N(psi(tau)), with the step
// integrals' integrands along the path. Shared by the explicit steps (explicit_steps.hpp) and the
// CVODE fallback (cvode_integrator.cpp); private to plant/.
#pragma once

#include <algorithm>

#include "ipmsm_ode.hpp"
#include "linear_flow.hpp"

namespace ipmsm {

// The integrator's y: the two flux components (z or psi) and the step integrals (cvode_integrator.hpp).
constexpr int kStates = 2 + StepIntegrands::count;

// Largest decay over one step, exp(-kStiffLimit), for which the linearised formulation is used:
// beyond it z = exp(-tau A) (...) grows like the decaying mode decays, and its error weights
// (relative to |z|) would no longer bound psi's error.
constexpr double kStiffLimit = 2.0;

// The step's linearisation at psi0 (cvode_integrator.hpp).
// The linear flow at one tau: exp(tau A), exp(-tau A), P(tau) (linear_flow.hpp).
struct FlowAt {
    double E[4], E_inv[4], P[4];
    // At tau + sigma from the flows at tau (this) and at sigma: exp((tau + sigma) A) =
    // exp(tau A) exp(sigma A), P(tau + sigma) = P(tau) + exp(tau A) P(sigma).
    FlowAt then(const FlowAt& s) const {
        FlowAt r;
        mul(E, s.E, r.E);
        mul(s.E_inv, E_inv, r.E_inv);
        double EP[4];
        mul(E, s.P, EP);
        for (int k = 0; k < 4; ++k) r.P[k] = P[k] + EP[k];
        return r;
    }
    static void mul(const double* a, const double* b, double* c) {
        c[0] = a[0] * b[0] + a[1] * b[2];
        c[1] = a[0] * b[1] + a[1] * b[3];
        c[2] = a[2] * b[0] + a[3] * b[2];
        c[3] = a[2] * b[1] + a[3] * b[3];
    }
};
struct Linearisation {
    double psi0[2], i0[2], G0[4], f0[2];
    LinearFlow flow;
    // At psi0 with its currents c (and dI/dpsi), f(psi0) = f and A = df/dpsi(psi0), row-major.
    void set(const double* psi, const InverseFluxPoint& c, const double* f, const double* A) {
        psi0[0] = psi[0];
        psi0[1] = psi[1];
        i0[0] = c.i_d;
        i0[1] = c.i_q;
        G0[0] = c.G_dd;
        G0[1] = c.G_dq;
        G0[2] = c.G_qd;
        G0[3] = c.G_qq;
        f0[0] = f[0];
        f0[1] = f[1];
        flow = LinearFlow(A);
    }
    FlowAt at(double tau) const {
        FlowAt F;
        flow.exp(tau, F.E, F.E_inv);
        flow.integral(tau, F.E, F.P);
        return F;
    }
    // psi(tau) for z, the flow at tau given.
    void psi_at(const FlowAt& F, const double* z, double* psi) const {
        psi[0] = psi0[0] + F.P[0] * f0[0] + F.P[1] * f0[1] + F.E[0] * z[0] + F.E[1] * z[1];
        psi[1] = psi0[1] + F.P[2] * f0[0] + F.P[3] * f0[1] + F.E[2] * z[0] + F.E[3] * z[1];
    }
    // The linearisation's currents at psi, i0 + G0 (psi - psi0): within a step the currents are
    // near them, so the inverse map's Newton starts there (one forward-map evaluation, not the
    // table's three).
    void predicted_currents(const double* psi, double* i) const {
        const double dd = psi[0] - psi0[0], dq = psi[1] - psi0[1];
        i[0] = i0[0] + G0[0] * dd + G0[1] * dq;
        i[1] = i0[1] + G0[2] * dd + G0[3] * dq;
    }
};

// One call's problem: the ODE's inputs, the step's linearisation and the integrands (a Problem of
// explicit_steps.hpp).
struct LinearisedProblem {
    static constexpr int kY = kStates;
    DqFluxOde ode;  // the RHS's data during advance()
    Linearisation lin;
    const StepIntegrands* integrands = nullptr;  // this call's, or none (their components' y' = 0)

    // The linearised right-hand side at tau for y = (z, step integrals), with the path's psi and
    // its currents.
    void linearised_rhs(const FlowAt& F, const double* y, double* d, double* psi, InverseFluxPoint& c) const {
        lin.psi_at(F, y, psi);
        double i_lin[2];
        lin.predicted_currents(psi, i_lin);
        c = ode.currents_near(psi[0], psi[1], i_lin[0], i_lin[1]);
        // The nonlinear remainder N = -R (i(psi) - i_lin(psi)), carried back by exp(-tau A).
        const double n0 = -ode.R * (c.i_d - i_lin[0]), n1 = -ode.R * (c.i_q - i_lin[1]);
        d[0] = F.E_inv[0] * n0 + F.E_inv[1] * n1;
        d[1] = F.E_inv[2] * n0 + F.E_inv[3] * n1;
        integrands_at(psi, c, d + 2);
    }

    // y' at tau = 0: z' = 0 (N(psi0) = 0), the integrands at the start's currents.
    void start_derivative(double* d) const {
        d[0] = d[1] = 0.0;
        const InverseFluxPoint c0{lin.i0[0], lin.i0[1], lin.G0[0], lin.G0[1], lin.G0[2], lin.G0[3]};
        integrands_at(lin.psi0, c0, d + 2);
    }

    // The right-hand side is smooth wherever the currents are found: no events.
    bool within(const InverseFluxPoint&) const { return true; }

    // The step integrals' integrands at psi with its currents c (zeros without integrands).
    void integrands_at(const double* psi, const InverseFluxPoint& c, double* q) const {
        if (integrands != nullptr)
            integrands->eval(ode, psi[0], psi[1], c.i_d, c.i_q, q);
        else
            std::fill(q, q + StepIntegrands::count, 0.0);
    }
};

}  // namespace ipmsm
