// The explicit steps of the plant's integrators (cvode_integrator.hpp, explicit_first; and the
// conducting bridge's, freewheel_integrator.hpp): embedded Bogacki-Shampine 3(2) steps across a
// call of a linearised step's remainder z and the step integrals, tried before CVODE; private to
// plant/.
//
// A Problem (linearised_step.hpp: LinearisedProblem; freewheel_integrator.cpp: the bridge's) has
//   kY                                   y's components: z (two), then the step integrals
//   lin                                  the step's Linearisation
//   start_derivative(k1)                 y' at tau = 0 (z' = 0 there: N(psi0) = 0)
//   linearised_rhs(F, y, d, psi, c)      y' at tau (the flow at tau F), with psi and its currents
//   within(c)                            false where the currents c leave the region where the
//                                        right-hand side is smooth (an event could be missed):
//                                        the explicit steps give up, CVODE decides
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

#include "cvode_integrator.hpp"
#include "linearised_step.hpp"

namespace ipmsm {

namespace explicit_detail {

// One Bogacki-Shampine 3(2) step of length dt from y with y' = k1 (Bogacki and Shampine, Appl.
// Math. Lett. 2 (1989) 321-325), the flows at its stages dt / 2, 3 dt / 4 and dt given: y_new,
// k4 = y'(y_new) (the next step's k1), psi and the currents there; returns the squared
// weighted norm of the embedded error estimate (CVODE's weights rtol |y_new| + atol, summed
// over y's components; NaN where the currents could not be found or left the problem's region).
template <class Problem>
double bs3_step(const Problem& p, const FlowAt& F2, const FlowAt& F3, const FlowAt& F4, double dt, const double* y,
                const double* k1, double rtol, const double* atol, double* y_new, double* k4, double* psi_new,
                InverseFluxPoint& c_new) {
    constexpr int n = Problem::kY;
    double k2[n], k3[n], ys[n], psi[2];
    InverseFluxPoint c2, c3;
    for (int k = 0; k < n; ++k) ys[k] = y[k] + 0.5 * dt * k1[k];
    p.linearised_rhs(F2, ys, k2, psi, c2);
    for (int k = 0; k < n; ++k) ys[k] = y[k] + 0.75 * dt * k2[k];
    p.linearised_rhs(F3, ys, k3, psi, c3);
    for (int k = 0; k < n; ++k) y_new[k] = y[k] + dt * (2.0 / 9.0 * k1[k] + 1.0 / 3.0 * k2[k] + 4.0 / 9.0 * k3[k]);
    p.linearised_rhs(F4, y_new, k4, psi_new, c_new);
    double sum = 0.0;
    for (int k = 0; k < n; ++k) {
        const double e = dt * (-5.0 / 72.0 * k1[k] + 1.0 / 12.0 * k2[k] + 1.0 / 9.0 * k3[k] - 0.125 * k4[k]);
        const double r = e / (rtol * std::abs(y_new[k]) + atol[k]);
        sum += r * r;
    }
    const bool found =
        std::isfinite(psi_new[0]) && std::isfinite(psi_new[1]) && std::isfinite(c_new.i_d) && std::isfinite(c_new.i_q);
    return found && p.within(c2) && p.within(c3) && p.within(c_new) ? sum : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace explicit_detail

// Explicit steps from y = 0 across the span (cvode_integrator.hpp): one Bogacki-Shampine step
// over the whole span; where its error estimate's weighted RMS norm exceeds 1, shorter steps
// under the standard step-size controller for a third-order pair (safety 0.9, a change per
// step within [0.2, 5]: Hairer, Norsett and Wanner, Solving Ordinary Differential Equations I,
// 2nd ed., section II.4). True, with y(span), psi(span), the currents there and the steps
// taken, when at most max_attempts attempts crossed the span (false as soon as the step
// length the estimates ask for says they will not, or where the currents could not be found or
// left the problem's region: CVODE decides).
template <class Problem>
bool explicit_steps(const Problem& p, double span, double rtol, const double* atol, int max_attempts, double* y_end,
                    double* psi_end, InverseFluxPoint& c_end, CvodeStats& st) {
    using explicit_detail::bs3_step;
    constexpr int n = Problem::kY;
    double k1[n], k4[n], y[n], y_new[n];
    std::fill(y, y + n, 0.0);
    p.start_derivative(k1);
    st = CvodeStats{};
    st.last_order = 3;
    st.rhs_evals = 3;
    st.explicit_only = true;  // unless it returns false
    // The whole span in one step: the flows at span / 2, 3 span / 4, span from the one at span / 4.
    const FlowAt G = p.lin.at(0.25 * span), G2 = G.then(G);
    double sum = bs3_step(p, G2, G2.then(G), G2.then(G2), span, y, k1, rtol, atol, y_end, k4, psi_end, c_end);
    if (sum <= n) {
        st.steps = 1;
        st.last_step = span;
        return true;
    }
    st.error_test_fails = 1;
    // Shorter steps from tau with y, the flow at tau F0.
    FlowAt F0 = p.lin.at(0.0);
    double tau = 0.0, dt = span;
    for (int attempt = 1;; ++attempt) {
        if (!std::isfinite(sum)) return false;
        const double norm = std::sqrt(sum / n);
        dt *= norm > 0.0 ? std::clamp(0.9 * std::cbrt(1.0 / norm), 0.2, 5.0) : 5.0;
        if ((span - tau) / dt > max_attempts - attempt) return false;  // would not fit in the attempts left
        const bool last = tau + dt >= span * (1.0 - 1e-12);
        if (last) dt = span - tau;
        const FlowAt H = p.lin.at(0.25 * dt), H2 = H.then(H), F2 = F0.then(H2), F4 = F2.then(H2);
        sum = bs3_step(p, F2, F2.then(H), F4, dt, y, k1, rtol, atol, y_new, k4, psi_end, c_end);
        st.rhs_evals += 3;
        if (sum <= n) {  // accepted; k4 is the next step's k1 (first same as last)
            ++st.steps;
            st.last_step = dt;
            if (last) {
                std::copy(y_new, y_new + n, y_end);
                return true;
            }
            tau += dt;
            std::copy(y_new, y_new + n, y);
            std::copy(k4, k4 + n, k1);
            F0 = F4;
        } else {
            ++st.error_test_fails;
        }
    }
}

}  // namespace ipmsm
