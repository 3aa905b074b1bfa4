// The explicit steps of the plant's integrator (cvode_integrator.hpp, explicit_first): embedded
// Bogacki-Shampine 3(2) steps across a call of the linearised step's remainder z and the step
// integrals, tried before CVODE; private to plant/.
#pragma once

#include "cvode_integrator.hpp"
#include "linearised_step.hpp"

namespace ipmsm {

// Explicit steps from y = 0 across the span (cvode_integrator.hpp): one Bogacki-Shampine step
// over the whole span; where its error estimate's weighted RMS norm exceeds 1, shorter steps
// under the standard step-size controller for a third-order pair (safety 0.9, a change per
// step within [0.2, 5]: Hairer, Norsett and Wanner, Solving Ordinary Differential Equations I,
// 2nd ed., section II.4). True, with y(span), psi(span), the currents there and the steps
// taken, when at most kMaxExplicitSteps attempts crossed the span (false as soon as the step
// length the estimates ask for says they will not, or where the currents could not be found:
// CVODE decides).
bool explicit_steps(const LinearisedProblem& p, double span, double rtol, const double* atol, double* y_end,
                    double* psi_end, InverseFluxPoint& c_end, CvodeStats& st);

}  // namespace ipmsm
