// The plant's integrator while the inverter freewheels (inverter_state.hpp): the flux linkages
// with the diode bridge's voltage u = -k i/|i| while it conducts, i = 0 while it blocks, and the
// exact switching between the two located by CVODE's root finding (docs/spec/MATH.md, "The
// inverter's safe states").
//
// Conducting, the bridge's voltage acts like a resistance k/|i| (several ohms at tens of amperes,
// against the winding's milliohms): the electrical time constant is tens of microseconds, shorter
// than a communication step, and it shortens without bound as |i| -> 0. Away from zero, the step
// is linearised at its start with the bridge's voltage's Jacobian in the linear part, whose flow is
// exact, and explicit steps integrate the remainder (as the switching path's, cvode_integrator.hpp;
// freewheel_integrator.cpp, ConductingStep; MATH.md, "The conducting bridge's linearised step"),
// halved down to 1/16 of the call where they miss the tolerances. Where they give up, or the
// current nears zero or crosses a root function's line, CVODE's BDF with Newton (the 2 x 2
// Jacobian analytic, dI/dpsi from the inverse map) integrates the rest of the call with the root
// finding below, with steps the solution's smoothness allows, not the stiffness.
//
// A current reaches zero in finite time along one of the decaying directions n_j
// (inverter_state.hpp: bridge_directions); each has a root function g_j = i . n_j. At the zero the
// bridge blocks where |e_0| < k; above the onset the current passes zero and grows again along the
// onset direction. The bridge's voltage, discontinuous at
// i = 0, is continued past the zero along n_j (u = -k sign(g_j) i/|i|, the same voltage on both
// sides of the line i = s n_j), so the step that crosses the zero sees a smooth right-hand side
// and the root is located on CVODE's interpolant; then psi = psi_0 for the rest of the step. The
// continuation applies only for a g_j that was > 0 at its segment's start ("armed", a falling root
// wanted), and only at small currents; an unarmed g_j watches for a rise through zero and arms
// there. A falling root where |i| is not near zero (the current crossed the line i = s n_j at
// amperes, as after a trip from motoring) is not a zero of the current: g_j goes on unarmed.
//
// Conduction starts only at a communication point (the inputs are held over a step, and so is
// |e_0| = |omega| |psi_0|), from psi_0 along the onset direction.
// A call starting within the zero tolerance of psi_0 (a current of rounding size) starts as from
// i = 0: blocked below the onset, along the onset direction above it.
//
// The integrator's state is the plant's (psi, blocked, the currents' Newton seed); CVODE is
// re-initialised at every call, so a call's result depends only on that state, the inputs and h.
#pragma once

#include <memory>

#include "cvode_integrator.hpp"
#include "ipmsm_ode.hpp"

namespace ipmsm {

// The result of one call.
struct FreewheelStep {
    double psi[2] = {0, 0};  // Wb, at the end
    InverseFluxPoint c{};    // the currents there (zero while blocked)
    bool blocked = false;    // at the end
    // The step integrals (StepIntegrands::Index) and int |i| dt (A.s), int |i|^2 dt (A^2.s).
    double integrals[StepIntegrands::count] = {0, 0, 0, 0};
    double I_integral = 0, I2_integral = 0;
    int switchings = 0;             // conduct -> block and block -> conduct in this call
    long steps = 0, rhs_evals = 0;  // CVODE's and the linearised step's explicit steps
    double h_last = 0;              // s, the last step size (CVODE's first in the next call; 0: none)
};

class FreewheelIntegrator {
public:
    FreewheelIntegrator();
    ~FreewheelIntegrator();
    FreewheelIntegrator(const FreewheelIntegrator&);  // no workspace: made on first use
    FreewheelIntegrator& operator=(const FreewheelIntegrator&);
    FreewheelIntegrator(FreewheelIntegrator&&) noexcept;
    FreewheelIntegrator& operator=(FreewheelIntegrator&&) noexcept;

    // One communication step of h seconds with the bridge amplitude k = 2 u_dc / pi (V), from psi
    // (Wb; while blocked, psi_0) with the currents' Newton seed i_seed (NaN: unknown) and CVODE's
    // first step h_start (s; 0: CVODE's estimate). ode's u_d, u_q are not used. Throws CvodeError.
    FreewheelStep advance(const DqFluxOde& ode, double k, const StepIntegrands& integrands, const CvodeSettings& s,
                          double h, const double* psi, bool blocked, const double* i_seed, double h_start);

private:
    struct Workspace;
    std::unique_ptr<Workspace> ws_;
};

}  // namespace ipmsm
