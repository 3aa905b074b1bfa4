#include "cvode_integrator.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>

#include <cvode/cvode.h>
#include <cvode/cvode_ls.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

#include "cvode_handles.hpp"
#include "explicit_steps.hpp"
#include "linearised_step.hpp"

namespace ipmsm {

namespace {

// The absolute tolerances of y's components: atol on the flux components, its equivalents on the
// step integrals (cvode_integrator.hpp).
std::array<double, kStates> tolerances(const CvodeSettings& s, const StepIntegrands* integrands, double span) {
    const double energy = 1.5 * s.atol * s.current_scale;                              // J
    const double impulse = energy * (integrands ? integrands->pole_pairs : 1) * span;  // N.m.s
    return {s.atol, s.atol, energy, energy, energy, impulse};
}

std::string number(double x) {
    char b[32];
    std::snprintf(b, sizeof b, "%.17g", x);
    return b;
}

std::string flag_name(int flag) {
    char* name = CVodeGetReturnFlagName(flag);  // malloc'd by CVODE
    std::string s = name != nullptr ? name : std::to_string(flag);
    std::free(name);
    return s;
}

// The linearisation at psi0: f0, A = -R G0 + omega J (ipmsm_ode.hpp); z(0) = 0. False where the
// electrical time constant is shorter than the step (a stiff map): z = exp(-tau A) (...) grows
// like a decaying mode decays, would be badly scaled, and CVODE integrates psi itself
// (cvode_method 2, BDF, is meant for those).
bool linearise(Linearisation& L, const CvodeState& start, const DqFluxOde& ode, double h) {
    double f0[2], A[4];
    const InverseFluxPoint c = ode.currents_near(start.psi[0], start.psi[1], start.i_seed[0], start.i_seed[1]);
    ode.rhs_and_jacobian(start.psi, c, f0, A);
    if (!std::isfinite(f0[0] + f0[1] + A[0] + A[1] + A[2] + A[3]))
        throw CvodeError("no finite currents at the step's start, psi_d = " + number(start.psi[0]) +
                         " Wb, psi_q = " + number(start.psi[1]) + " Wb");
    L.set(start.psi, c, f0, A);
    return L.flow.max_decay() * h <= kStiffLimit;
}

}  // namespace

// The CVODE objects of one integrator and the data CVODE's callbacks see: scratch memory, never
// copied, at a fixed address (the callbacks' user data).
// CVODE's y is z in the linearised formulation (linearised_step.hpp), psi in the direct one.
struct CvodeIntegrator::Workspace : LinearisedProblem {
    CvodeSettings built_for;  // structure
    bool linearised = false;  // this call's formulation (built_for.linearised unless too stiff)
    std::string bad_flux;     // where the currents could not be found (for the error message)
    std::string error;        // CVODE's error messages of the current call
    std::string warning;      // CVODE's warnings of the current call
    // Tolerances given to CVODE (CVodeSVtolerances clears CVODE's error-weight data until its next
    // initial setup, so it is called only when they change, and then CVODE is re-initialised).
    double rtol = 0, atol[kStates] = {0, 0, 0, 0, 0, 0};
    CvodeHandles h;  // last member: destroyed first, while the data above still exists

    explicit Workspace(const CvodeSettings& s);
    Workspace(const Workspace&) = delete;
    Workspace& operator=(const Workspace&) = delete;

    // CVodeSVtolerances, only when they change (it resets CVODE's error weights).
    void set_tolerances(double r, const double* a) {
        bool same = r == rtol;
        for (int k = 0; k < kStates; ++k) same = same && a[k] == atol[k];
        if (same) return;
        rtol = 0;  // unknown until the call succeeds
        double* v = N_VGetArrayPointer(h.atol);
        for (int k = 0; k < kStates; ++k) v[k] = atol[k] = a[k];
        check(CVodeSVtolerances(h.mem, r, h.atol), "CVodeSVtolerances");
        rtol = r;
    }
    bool same_tolerances(double r, const double* a) const {
        bool same = r == rtol;
        for (int k = 0; k < kStates; ++k) same = same && a[k] == atol[k];
        return same;
    }

    void check(int flag, const char* call) {
        if (flag >= 0) return;
        std::string m = std::string("CVODE ") + call + " failed (" + flag_name(flag) + ")";
        if (!error.empty()) m += ": " + error;
        throw CvodeError(m);
    }

    // Non-finite: recoverable, CVODE retries with a smaller step (and fails if it persists).
    int finite_or_retry(const double* psi, const double* d) {
        if (std::isfinite(d[0]) && std::isfinite(d[1])) return 0;
        bad_flux = "psi_d = " + number(psi[0]) + " Wb, psi_q = " + number(psi[1]) + " Wb";
        return 1;
    }

    // y = (the two flux components, the step integrals); the integrals' y' are the integrands at
    // the path's flux linkages, from the same inverse-map evaluation as the flux components'.
    static int rhs(realtype tau, N_Vector y, N_Vector ydot, void* data) {
        auto* w = static_cast<Workspace*>(data);
        const double* p = N_VGetArrayPointer(y);
        double* d = N_VGetArrayPointer(ydot);
        double psi[2];
        InverseFluxPoint c;
        if (w->linearised) {
            w->linearised_rhs(w->lin.at(tau), p, d, psi, c);
        } else {
            psi[0] = p[0];
            psi[1] = p[1];
            c = w->ode.currents(psi[0], psi[1]);
            d[0] = w->ode.u_d - w->ode.R * c.i_d + w->ode.omega * psi[1];
            d[1] = w->ode.u_q - w->ode.R * c.i_q - w->ode.omega * psi[0];
            w->integrands_at(psi, c, d + 2);
        }
        double sum = 0.0;
        for (int k = 0; k < kStates; ++k) sum += d[k];
        const double all[2] = {sum, sum};
        return w->finite_or_retry(psi, all);
    }

    static int jac(realtype tau, N_Vector y, N_Vector, SUNMatrix J, void* data, N_Vector, N_Vector, N_Vector) {
        auto* w = static_cast<Workspace*>(data);
        double j[4];
        if (!w->linearised) {
            w->ode.jacobian(N_VGetArrayPointer(y), j);
        } else {
            // d z' / d z = exp(-tau A) (-R) (G(psi) - G0) exp(tau A)
            const Linearisation& L = w->lin;
            const FlowAt F = L.at(tau);
            const double *E = F.E, *E_inv = F.E_inv;
            double psi[2];
            L.psi_at(F, N_VGetArrayPointer(y), psi);
            const InverseFluxPoint c = w->ode.currents(psi[0], psi[1]);
            const double R = w->ode.R;
            const double D[4] = {-R * (c.G_dd - L.G0[0]), -R * (c.G_dq - L.G0[1]), -R * (c.G_qd - L.G0[2]),
                                 -R * (c.G_qq - L.G0[3])};
            const double DE[4] = {D[0] * E[0] + D[1] * E[2], D[0] * E[1] + D[1] * E[3], D[2] * E[0] + D[3] * E[2],
                                  D[2] * E[1] + D[3] * E[3]};
            j[0] = E_inv[0] * DE[0] + E_inv[1] * DE[2];
            j[1] = E_inv[0] * DE[1] + E_inv[1] * DE[3];
            j[2] = E_inv[2] * DE[0] + E_inv[3] * DE[2];
            j[3] = E_inv[2] * DE[1] + E_inv[3] * DE[3];
        }
        // The step integrals' rows and columns stay zero: they do not feed back, so Newton with
        // this matrix converges as fast as on the flux components alone.
        SM_ELEMENT_D(J, 0, 0) = j[0];
        SM_ELEMENT_D(J, 0, 1) = j[1];
        SM_ELEMENT_D(J, 1, 0) = j[2];
        SM_ELEMENT_D(J, 1, 1) = j[3];
        return std::isfinite(j[0] + j[1] + j[2] + j[3]) ? 0 : 1;
    }

    // CVODE's messages go here instead of stderr; the integrator raises them as CvodeError.
    static void handler(int code, const char* module, const char* function, char* msg, void* data) {
        auto* w = static_cast<Workspace*>(data);
        try {
            std::string& to = code == CV_WARNING ? w->warning : w->error;
            if (!to.empty()) to += "; ";
            to += std::string(module != nullptr ? module : "CVODE") + "/" + (function != nullptr ? function : "?") +
                  ": " + (msg != nullptr ? msg : "");
        } catch (...) {}
    }
};

CvodeIntegrator::Workspace::Workspace(const CvodeSettings& s) : built_for(s) {
    // On a throw, h's destructor frees whatever was made so far.
    if (SUNContext_Create(nullptr, &h.ctx) != 0 || h.ctx == nullptr) throw CvodeError("SUNContext_Create failed");
    h.y = N_VNew_Serial(kStates, h.ctx);
    h.atol = N_VNew_Serial(kStates, h.ctx);
    if (h.y == nullptr || h.atol == nullptr) throw CvodeError("N_VNew_Serial failed");
    N_VConst(0.0, h.y);
    h.mem = CVodeCreate(s.method == CvodeMethod::bdf ? CV_BDF : CV_ADAMS, h.ctx);
    if (h.mem == nullptr) throw CvodeError("CVodeCreate failed");
    check(CVodeSetErrHandlerFn(h.mem, &Workspace::handler, this), "CVodeSetErrHandlerFn");
    check(CVodeInit(h.mem, &Workspace::rhs, 0.0, h.y), "CVodeInit");
    check(CVodeSetUserData(h.mem, this), "CVodeSetUserData");
    set_tolerances(s.rtol, tolerances(s, nullptr, 1.0).data());
    if (s.nonlinear == CvodeNonlinear::fixed_point) {
        h.nls = SUNNonlinSol_FixedPoint(h.y, 0, h.ctx);
        if (h.nls == nullptr) throw CvodeError("SUNNonlinSol_FixedPoint failed");
        check(CVodeSetNonlinearSolver(h.mem, h.nls), "CVodeSetNonlinearSolver");
    } else {
        h.A = SUNDenseMatrix(kStates, kStates, h.ctx);
        if (h.A == nullptr) throw CvodeError("SUNDenseMatrix failed");
        h.ls = SUNLinSol_Dense(h.y, h.A, h.ctx);
        if (h.ls == nullptr) throw CvodeError("SUNLinSol_Dense failed");
        check(CVodeSetLinearSolver(h.mem, h.ls, h.A), "CVodeSetLinearSolver");
        if (s.nonlinear == CvodeNonlinear::newton_analytic)
            check(CVodeSetJacFn(h.mem, &Workspace::jac), "CVodeSetJacFn");
    }
    if (s.max_order > 0) check(CVodeSetMaxOrd(h.mem, s.max_order), "CVodeSetMaxOrd");
    if (s.nonlin_conv_coef > 0) check(CVodeSetNonlinConvCoef(h.mem, s.nonlin_conv_coef), "CVodeSetNonlinConvCoef");
}

CvodeIntegrator::CvodeIntegrator(const CvodeSettings& settings) : settings_(settings) {}
CvodeIntegrator::~CvodeIntegrator() = default;

CvodeIntegrator::CvodeIntegrator(const CvodeIntegrator& o)
    : settings_(o.settings_), state_(o.state_), stats_(o.stats_), warnings_(o.warnings_) {
    std::copy(o.integrals_, o.integrals_ + StepIntegrands::count, integrals_);
}

CvodeIntegrator& CvodeIntegrator::operator=(const CvodeIntegrator& o) {
    if (this == &o) return *this;
    settings_ = o.settings_;
    state_ = o.state_;
    stats_ = o.stats_;
    std::copy(o.integrals_, o.integrals_ + StepIntegrands::count, integrals_);
    warnings_ = o.warnings_;
    if (ws_ && !ws_->built_for.same_structure(settings_)) ws_.reset();
    return *this;
}

CvodeIntegrator::CvodeIntegrator(CvodeIntegrator&& o) noexcept = default;
CvodeIntegrator& CvodeIntegrator::operator=(CvodeIntegrator&& o) noexcept = default;

void CvodeIntegrator::reset(double t, double psi_d, double psi_q) {
    state_ = CvodeState{};
    state_.t = t;
    state_.psi[0] = psi_d;
    state_.psi[1] = psi_q;
    stats_ = CvodeStats{};
    std::fill(integrals_, integrals_ + StepIntegrands::count, 0.0);
    warnings_.clear();
}

double CvodeIntegrator::initial_step(const DqFluxOde& ode, double span, bool linearised) const {
    switch (settings_.init_step) {
        case CvodeInitStep::curvature:
            // linearised: z(0) = z'(0) = z''(0) = 0 (N and its gradient vanish at psi0), so the
            // order-1 start has no curvature to resolve: try the whole step.
            if (linearised) return span;
            break;
        case CvodeInitStep::previous_last: return std::min(state_.h_next, span);
    }
    // Order 1 (where CVODE restarts) has the local error about h^2/2 |y''|; CVODE accepts a step
    // when its weighted RMS norm is <= 1 (weights 1 / (rtol |y| + atol)). Aim at a quarter of
    // that, so that the first step is rarely rejected and, in steady state, is the whole span.
    const double* y = state_.psi;
    double f[2], J[4];
    ode.rhs_and_jacobian(y, f, J);
    const double a0 = (J[0] * f[0] + J[1] * f[1]) / (settings_.rtol * std::abs(y[0]) + settings_.atol);
    const double a1 = (J[2] * f[0] + J[3] * f[1]) / (settings_.rtol * std::abs(y[1]) + settings_.atol);
    const double ydd = std::sqrt(0.5 * (a0 * a0 + a1 * a1));  // weighted RMS norm of y''
    if (!(ydd > 0) || !std::isfinite(ydd)) return std::isfinite(ydd) ? span : 0.0;
    return std::min(span, std::sqrt(2.0 * settings_.init_step_error / ydd));
}

CvodeIntegrator::Workspace& CvodeIntegrator::workspace() {
    if (!ws_ || !ws_->built_for.same_structure(settings_)) {
        ws_.reset();
        ws_ = std::make_unique<Workspace>(settings_);
    }
    return *ws_;
}

void CvodeIntegrator::advance(const DqFluxOde& ode, double h, const StepIntegrands* integrands) {
    if (!(h > 0) || !std::isfinite(h))
        throw CvodeError("CvodeIntegrator::advance: the step h = " + number(h) + " s is not positive and finite");
    if (!(settings_.rtol > 0) || !(settings_.atol > 0)) throw CvodeError("CvodeIntegrator: rtol and atol must be > 0");
    Workspace& w = workspace();
    w.ode = ode;
    w.error.clear();
    w.warning.clear();
    w.bad_flux.clear();
    const std::array<double, kStates> atol = tolerances(settings_, integrands, h);
    const bool new_tolerances = !w.same_tolerances(settings_.rtol, atol.data());
    w.linearised = settings_.linearised && linearise(w.lin, state_, ode, h);
    double* y = N_VGetArrayPointer(w.h.y);
    if (w.linearised) {
        y[0] = y[1] = 0.0;
    } else {
        y[0] = state_.psi[0];
        y[1] = state_.psi[1];
    }
    std::fill(y + 2, y + kStates, 0.0);  // the step integrals
    w.integrands = integrands;
    if (w.linearised && settings_.explicit_first) {  // explicit steps first (explicit_steps.hpp)
        double y_end[kStates], psi_end[2];
        InverseFluxPoint c_end;
        CvodeStats est;
        if (explicit_steps(static_cast<const LinearisedProblem&>(w), h, settings_.rtol, atol.data(),
                           settings_.explicit_attempts, y_end, psi_end, c_end, est)) {
            commit(h, psi_end, c_end, h, est, y_end + 2, w.warning);
            return;
        }
    }
    double integrals[StepIntegrands::count] = {0, 0, 0, 0};
    const CvodeStats st = integrate(w, ode, h, atol.data(), new_tolerances, integrals);
    double psi_end[2];
    const InverseFluxPoint c_end = end_point(w, ode, h, psi_end);
    const double h_next = st.last_step;
    commit(h, psi_end, c_end, h_next > 0 && std::isfinite(h_next) ? h_next : 0.0, st, integrals, w.warning);
}

// CVODE from tau = 0 to h, re-initialised at y (time relative to the step's start).
CvodeStats CvodeIntegrator::integrate(Workspace& w, const DqFluxOde& ode, double h, const double* atol,
                                      bool new_tolerances, double* integrals) const {
    void* mem = w.h.mem;
    const double tau_end = h;
    w.check(CVodeReInit(mem, 0.0, w.h.y), "CVodeReInit");
    w.check(CVodeSetInitStep(mem, initial_step(ode, h, w.linearised)), "CVodeSetInitStep");
    if (new_tolerances) w.set_tolerances(settings_.rtol, atol);
    w.check(CVodeSetMaxNumSteps(mem, settings_.max_steps), "CVodeSetMaxNumSteps");
    w.check(CVodeSetStopTime(mem, tau_end), "CVodeSetStopTime");
    double t_ret = 0.0;
    const int flag = CVode(mem, tau_end, w.h.y, &t_ret, CV_NORMAL);
    if (flag < 0) {
        std::string m = "CVODE failed over a step of " + number(h) + " s (" + flag_name(flag) + ")";
        if (!w.error.empty()) m += ": " + w.error;
        if (!w.bad_flux.empty())
            m += "; no finite currents at " + w.bad_flux +
                 " (the flux linkages left what the flux map and its continuation can invert)";
        throw CvodeError(m);
    }
    const double* y = N_VGetArrayPointer(w.h.y);
    if (!std::isfinite(y[0]) || !std::isfinite(y[1]))
        throw CvodeError("CVODE returned non-finite flux linkages at the end of a step of " + number(h) + " s");
    for (int k = 0; k < StepIntegrands::count; ++k) {
        integrals[k] = y[2 + k];
        if (!std::isfinite(integrals[k]))
            throw CvodeError("non-finite step integrals at the end of a step of " + number(h) + " s");
    }
    CvodeStats st;
    CVodeGetNumSteps(mem, &st.steps);
    CVodeGetNumRhsEvals(mem, &st.rhs_evals);
    CVodeGetNumErrTestFails(mem, &st.error_test_fails);
    CVodeGetNumNonlinSolvIters(mem, &st.nonlinear_iterations);
    CVodeGetNumNonlinSolvConvFails(mem, &st.nonlinear_failures);
    CVodeGetLastOrder(mem, &st.last_order);
    CVodeGetLastStep(mem, &st.last_step);
    return st;
}

// The flux linkages at the step's end (linearised: psi(h) from z(h)) and the currents there,
// from the linearisation's prediction as in linearised_rhs, else from the inverse map's table.
InverseFluxPoint CvodeIntegrator::end_point(Workspace& w, const DqFluxOde& ode, double h, double* psi_end) const {
    const double* y = N_VGetArrayPointer(w.h.y);
    psi_end[0] = y[0];
    psi_end[1] = y[1];
    if (!w.linearised) return ode.currents(psi_end[0], psi_end[1]);
    w.lin.psi_at(w.lin.at(h), y, psi_end);
    if (!std::isfinite(psi_end[0]) || !std::isfinite(psi_end[1]))
        throw CvodeError("non-finite flux linkages at the end of a step of " + number(h) + " s");
    double i_lin[2];
    w.lin.predicted_currents(psi_end, i_lin);
    return ode.currents_near(psi_end[0], psi_end[1], i_lin[0], i_lin[1]);
}

void CvodeIntegrator::commit(double h, const double* psi_end, const InverseFluxPoint& c_end, double h_next,
                             const CvodeStats& stats, const double* integrals, const std::string& warnings) {
    end_currents_ = c_end;
    state_.i_seed[0] = c_end.i_d;  // the next call's Newton seed
    state_.i_seed[1] = c_end.i_q;
    state_.t += h;
    state_.psi[0] = psi_end[0];
    state_.psi[1] = psi_end[1];
    state_.h_next = h_next;
    stats_ = stats;
    std::copy(integrals, integrals + StepIntegrands::count, integrals_);
    warnings_ = warnings;
}

}  // namespace ipmsm
