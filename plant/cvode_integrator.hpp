// CVODE (SUNDIALS 6.x, linked statically) for the plant's two flux-linkage states, wrapped so
// that the plant model stays an ordinary copyable value.
//
// What CVODE integrates (linearised = true, the default): each call linearises the dq equations
// at its start psi0, f(psi) = f0 + A (psi - psi0) + N(psi) with A = df/dpsi(psi0) (the rotation
// omega J and -R di/dpsi) and the remainder N(psi) = -R (i(psi) - i(psi0) - di/dpsi (psi - psi0)),
// of second order in psi - psi0 and zero for a linear map. The linear part's flow is exact
// (linear_flow.hpp): psi(tau) = psi0 + P(tau) f0 + exp(tau A) z(tau), and CVODE integrates
//     z' = exp(-tau A) N(psi(tau)),  z(0) = 0,
// an equivalent ODE whose right-hand side is small and slowly varying: the dq frame's rotation
// (omega tau up to several radians per step) no longer limits CVODE's step, a step's error is
// what the tolerances allow on z, and a linear machine is integrated exactly. linearised =
// false integrates d psi / dt = f(psi) itself (kept for the benchmark's comparison), as does a
// call whose step is longer than twice the machine's fastest electrical time constant (a stiff
// map: z would grow like the decaying mode decays, exp(-tau A) being large).
//
// Time is relative: CVODE runs from tau = 0 to the step h of each call, so the result does not
// depend on the absolute time (a master starting at t = 1.7e9 s gets what one starting at 0
// gets); state().t is bookkeeping only.
//
// The integrator's state is plain data: the time, the flux linkages and the initial step size for
// the next call. CVODE is re-initialised at every call of advance() (every
// communication point): the inputs jump there anyway, and then the result of a call depends only
// on that plain state, the ODE's inputs and the settings, never on CVODE's history. This makes
// copies, FMU-state rollback and serialisation exact (bit-identical outputs) without touching
// CVODE's internals. The CVODE objects (context, vector, solver memory, nonlinear and linear
// solvers) live in a workspace that is scratch memory: created lazily on the first advance(),
// kept by copy-assignment (which the FMI glue does once per step, so it must be cheap), never
// copied (a copy gets a fresh workspace when it first integrates), and freed CVODE first, then the
// solver objects, the vector and the context it points into.
//
// The step's integrals (integrands given to advance()): quadratures of the StepIntegrands
// (ipmsm_ode.hpp) at the flux linkages along the path CVODE integrates, psi(tau) in either
// formulation. CVODE proper has no quadrature module (CVODES has), so they are four more
// components of y, q' = integrand(psi(tau)), q(0) = 0: under CVODE's error control like the
// flux components (what CVodeSetQuadErrCon gives), with the relative tolerance rtol and absolute
// tolerances that are atol's equivalents (what a flux error of atol means for an energy, 1.5 atol
// current_scale J, and for the torque's impulse over the step, 1.5 p atol current_scale h N.m.s);
// their integrands come from the inverse-map evaluation the flux components make anyway. They
// restart from 0 at every call: step_integrals() are the last call's.
//
// explicit_first (with linearised): before CVODE, explicit Runge-Kutta steps across the call (Bogacki-Shampine 3(2), three evaluations of the right-hand side per step; the
// first stage is known: z' = 0 at tau = 0, and later ones reuse the last stage) of z and the step
// integrals, each step's embedded error estimate measured in CVODE's weighted RMS norm with the
// same tolerances (weights rtol |y| + atol at the step's end). The first step spans the whole
// call; where the estimate misses, shorter ones follow under the standard step-size controller,
// and after explicit_attempts attempts CVODE integrates the call as without them. The remainder
// z is of second order in the step's change of psi, so one step passes where the currents change
// smoothly over the call; the step integrals' integrands carry the currents' whole change (at
// high speed, a rotation of the frame by omega h within the call), and there a few shorter steps
// meet the tolerances where CVODE, restarting at order 1 from each call's inputs, would need
// many. The CVODE set-up (re-initialisation, initial setup, the Nordsieck history) is paid only
// where the explicit steps give up.
//
// The currents at the end of a call (end_currents()) are the inverse map's at the end's flux
// linkages, with Newton started from the call's linearisation (InverseFluxMap::eval_near); the
// next call's linearisation evaluates them afresh with Newton started from them (state().i_seed,
// part of the state: a call's result depends on its start state only, copies and restored
// states are exact), or from the map's table where the seed is unknown (NaN, after reset()).
#pragma once

#include <limits>
#include <memory>
#include <stdexcept>
#include <string>

#include "ipmsm_ode.hpp"

namespace ipmsm {

// A failure of CVODE, with CVODE's own message (captured by its error handler, not printed).
struct CvodeError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

enum class CvodeMethod : int { adams = 1, bdf = 2 };

enum class CvodeNonlinear : int {
    fixed_point = 0,      // functional iteration: no Jacobian, no linear solver
    newton_analytic = 1,  // Newton, dense 2 x 2 linear solver, Jacobian from the inverse map's dI/dpsi
    newton_dq = 2,        // Newton, dense linear solver, CVODE's difference-quotient Jacobian
};

// Initial step size after a re-initialisation.
enum class CvodeInitStep : int {
    previous_last = 1,  // the last internal step size of the previous call (first call: CVODE's estimate)
    curvature = 3,      // from the solution's second derivative at the start, y'' = J f(y)
                        // (J from the inverse map's dI/dpsi): the step whose order-1 local error
                        // meets the tolerance; the whole interval if y'' = 0
};

struct CvodeSettings {
    CvodeMethod method = CvodeMethod::adams;
    CvodeNonlinear nonlinear = CvodeNonlinear::fixed_point;
    int max_order = 0;       // 0: the method's maximum (Adams 12, BDF 5)
    long max_steps = 10000;  // internal steps per advance() before CVODE gives up
    double rtol = 1e-6;      // relative tolerance
    double atol = 1e-6;      // absolute tolerance on the flux linkages, Wb
    bool linearised = true;  // integrate the remainder of the step's linearisation (above)
    CvodeInitStep init_step = CvodeInitStep::previous_last;
    double init_step_error = 0.25;  // curvature: the first step's aimed error, fraction of the tolerance
    double nonlin_conv_coef = 0;    // CVodeSetNonlinConvCoef; 0: CVODE's default 0.1
    double current_scale = 1e3;     // A: the quadratures' absolute tolerances (above)
    bool explicit_first = false;    // try embedded Runge-Kutta steps before CVODE (above)
    // Attempts of explicit steps across one call before CVODE integrates it instead: a call that
    // needs more is stiff or has a kink the third-order method cannot step over cheaply.
    int explicit_attempts = 8;

    // Settings that shape CVODE's objects (a workspace is reused only if they match).
    bool same_structure(const CvodeSettings& o) const {
        return method == o.method && nonlinear == o.nonlinear && max_order == o.max_order &&
               nonlin_conv_coef == o.nonlin_conv_coef && linearised == o.linearised;
    }
};

// The exact state of the integrator (what a copy or a serialised FMU state must carry).
struct CvodeState {
    double t = 0;            // the end of the last step (bookkeeping: the integration is in relative time)
    double psi[2] = {0, 0};  // psi_d, psi_q, Wb
    double h_next = 0;       // initial step size for the next advance(), s; 0: CVODE estimates
    // The currents at psi (A) from the last advance(), where the next one's Newton starts; NaN:
    // unknown, the inverse map's table gives the start.
    double i_seed[2] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN()};
};

// Counters of the last advance().
struct CvodeStats {
    long steps = 0, rhs_evals = 0, error_test_fails = 0, nonlinear_iterations = 0, nonlinear_failures = 0;
    int last_order = 0;
    double last_step = 0;
    bool explicit_only = false;  // the call was finished by the explicit steps (explicit_first), not CVODE
};

class CvodeIntegrator {
public:
    explicit CvodeIntegrator(const CvodeSettings& settings = {});
    ~CvodeIntegrator();
    CvodeIntegrator(const CvodeIntegrator& other);             // state and settings, no workspace
    CvodeIntegrator& operator=(const CvodeIntegrator& other);  // keeps this workspace if compatible
    CvodeIntegrator(CvodeIntegrator&& other) noexcept;
    CvodeIntegrator& operator=(CvodeIntegrator&& other) noexcept;

    // A new initial value (forgets the step-size hint).
    void reset(double t, double psi_d, double psi_q);

    // Integrates over a step of h > 0 seconds from state() with the ODE's inputs held (in
    // relative time: the result does not depend on state().t, which then grows by h). Throws
    // CvodeError (CVODE's message) and leaves the state unchanged if CVODE fails.
    // linearised: a call's result depends only on state().psi,
    // state().h_next (unused by the default initial step), the ODE and h.
    // integrands: the step's integrals of these too (step_integrals()).
    void advance(const DqFluxOde& ode, double h, const StepIntegrands* integrands = nullptr);

    const CvodeState& state() const { return state_; }
    void set_state(const CvodeState& s) { state_ = s; }
    const CvodeSettings& settings() const { return settings_; }
    // Tolerances and step limit may change between calls; the structure (method, nonlinear
    // solver, order) may too, at the cost of a new workspace on the next advance().
    void set_settings(const CvodeSettings& s) { settings_ = s; }
    const CvodeStats& stats() const { return stats_; }
    // The integrals over the last advance() of the integrands it was given (indices
    // StepIntegrands::Index; zeros if none were given).
    const double* step_integrals() const { return integrals_; }
    // The inverse map's currents (and dI/dpsi) at state().psi after the last advance().
    const InverseFluxPoint& end_currents() const { return end_currents_; }
    // CVODE's warnings (not errors) during the last advance(), "" if none.
    const std::string& warnings() const { return warnings_; }

private:
    struct Workspace;
    Workspace& workspace();
    double initial_step(const DqFluxOde& ode, double span, bool linearised) const;
    // advance()'s jobs after the step's linearisation (cvode_integrator.cpp) and the explicit
    // steps: CVODE over the step (its counters and the step integrals), the end's flux linkages
    // and currents.
    CvodeStats integrate(Workspace& w, const DqFluxOde& ode, double h, const double* atol, bool new_tolerances,
                         double* integrals) const;
    InverseFluxPoint end_point(Workspace& w, const DqFluxOde& ode, double h, double* psi_end) const;

    CvodeSettings settings_;
    CvodeState state_;
    CvodeStats stats_;
    double integrals_[StepIntegrands::count] = {0, 0, 0, 0};
    InverseFluxPoint end_currents_{};  // at state_.psi after the last advance()
    // A call's result becomes the state (after CVODE or after the explicit steps alike).
    void commit(double h, const double* psi_end, const InverseFluxPoint& c_end, double h_next, const CvodeStats& stats,
                const double* integrals, const std::string& warnings);
    std::string warnings_;
    std::unique_ptr<Workspace> ws_;
};

}  // namespace ipmsm
