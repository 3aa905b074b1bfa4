#include "explicit_steps.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ipmsm {

namespace {

// Attempts of explicit steps across one call before CVODE integrates it instead: a call that
// needs more is stiff or has a kink the third-order method cannot step over cheaply.
constexpr int kMaxExplicitSteps = 8;

// One Bogacki-Shampine 3(2) step of length dt from y with y' = k1 (Bogacki and Shampine, Appl.
// Math. Lett. 2 (1989) 321-325), the flows at its stages dt / 2, 3 dt / 4 and dt given: y_new,
// k4 = y'(y_new) (the next step's k1), psi and the currents there; returns the squared
// weighted norm of the embedded error estimate (CVODE's weights rtol |y_new| + atol, summed
// over y's components; NaN where the currents could not be found).
double bs3_step(const LinearisedProblem& p, const FlowAt& F2, const FlowAt& F3, const FlowAt& F4, double dt,
                const double* y, const double* k1, double rtol, const double* atol, double* y_new, double* k4,
                double* psi_new, InverseFluxPoint& c_new) {
    double k2[kStates], k3[kStates], ys[kStates], psi[2];
    InverseFluxPoint c;
    for (int k = 0; k < kStates; ++k) ys[k] = y[k] + 0.5 * dt * k1[k];
    p.linearised_rhs(F2, ys, k2, psi, c);
    for (int k = 0; k < kStates; ++k) ys[k] = y[k] + 0.75 * dt * k2[k];
    p.linearised_rhs(F3, ys, k3, psi, c);
    for (int k = 0; k < kStates; ++k)
        y_new[k] = y[k] + dt * (2.0 / 9.0 * k1[k] + 1.0 / 3.0 * k2[k] + 4.0 / 9.0 * k3[k]);
    p.linearised_rhs(F4, y_new, k4, psi_new, c_new);
    double sum = 0.0;
    for (int k = 0; k < kStates; ++k) {
        const double e = dt * (-5.0 / 72.0 * k1[k] + 1.0 / 12.0 * k2[k] + 1.0 / 9.0 * k3[k] - 0.125 * k4[k]);
        const double r = e / (rtol * std::abs(y_new[k]) + atol[k]);
        sum += r * r;
    }
    const bool found =
        std::isfinite(psi_new[0]) && std::isfinite(psi_new[1]) && std::isfinite(c_new.i_d) && std::isfinite(c_new.i_q);
    return found ? sum : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace

bool explicit_steps(const LinearisedProblem& p, double span, double rtol, const double* atol, double* y_end,
                    double* psi_end, InverseFluxPoint& c_end, CvodeStats& st) {
    double k1[kStates], k4[kStates], y[kStates] = {0, 0, 0, 0, 0, 0}, y_new[kStates];
    // tau = 0: z = 0, psi = psi0, N(psi0) = 0; the integrands at the start's currents.
    k1[0] = k1[1] = 0.0;
    const InverseFluxPoint c0{p.lin.i0[0], p.lin.i0[1], p.lin.G0[0], p.lin.G0[1], p.lin.G0[2], p.lin.G0[3]};
    p.integrands_at(p.lin.psi0, c0, k1 + 2);
    st = CvodeStats{};
    st.last_order = 3;
    st.rhs_evals = 3;
    st.explicit_only = true;  // unless it returns false
    // The whole span in one step: the flows at span / 2, 3 span / 4, span from the one at span / 4.
    const FlowAt G = p.lin.at(0.25 * span), G2 = G.then(G);
    double sum = bs3_step(p, G2, G2.then(G), G2.then(G2), span, y, k1, rtol, atol, y_end, k4, psi_end, c_end);
    if (sum <= kStates) {
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
        const double norm = std::sqrt(sum / kStates);
        dt *= norm > 0.0 ? std::clamp(0.9 * std::cbrt(1.0 / norm), 0.2, 5.0) : 5.0;
        if ((span - tau) / dt > kMaxExplicitSteps - attempt) return false;  // would not fit in the attempts left
        const bool last = tau + dt >= span * (1.0 - 1e-12);
        if (last) dt = span - tau;
        const FlowAt H = p.lin.at(0.25 * dt), H2 = H.then(H), F2 = F0.then(H2), F4 = F2.then(H2);
        sum = bs3_step(p, F2, F2.then(H), F4, dt, y, k1, rtol, atol, y_new, k4, psi_end, c_end);
        st.rhs_evals += 3;
        if (sum <= kStates) {  // accepted; k4 is the next step's k1 (first same as last)
            ++st.steps;
            st.last_step = dt;
            if (last) {
                std::copy(y_new, y_new + kStates, y_end);
                return true;
            }
            tau += dt;
            std::copy(y_new, y_new + kStates, y);
            std::copy(k4, k4 + kStates, k1);
            F0 = F4;
        } else {
            ++st.error_test_fails;
        }
    }
}

}  // namespace ipmsm
