#include "cvode_integrator.hpp"

#include <algorithm>
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

namespace ipmsm {

namespace {

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

}  // namespace

// The SUNDIALS objects, freed CVODE first (it refers to the solvers, the vector and the
// context), the context last.
struct CvodeHandles {
    SUNContext ctx = nullptr;
    N_Vector y = nullptr;
    void* mem = nullptr;
    SUNNonlinearSolver nls = nullptr;
    SUNMatrix A = nullptr;
    SUNLinearSolver ls = nullptr;

    CvodeHandles() = default;
    CvodeHandles(const CvodeHandles&) = delete;
    CvodeHandles& operator=(const CvodeHandles&) = delete;
    ~CvodeHandles() {
        if (mem != nullptr) CVodeFree(&mem);
        if (ls != nullptr) SUNLinSolFree(ls);
        if (A != nullptr) SUNMatDestroy(A);
        if (nls != nullptr) SUNNonlinSolFree(nls);
        if (y != nullptr) N_VDestroy(y);
        if (ctx != nullptr) SUNContext_Free(&ctx);
    }
};

// The CVODE objects of one integrator and the data CVODE's callbacks see: scratch memory, never
// copied, at a fixed address (the callbacks' user data).
struct CvodeIntegrator::Workspace {
    CvodeSettings built_for;  // structure
    DqFluxOde ode;            // the RHS's data during advance()
    std::string error;        // CVODE's error messages of the current call
    std::string warning;      // CVODE's warnings of the current call
    // reinit_each_step = false: where CVODE's history stands, to know whether it continues.
    bool live = false;
    double live_t = 0, live_psi[2] = {0, 0};
    // Tolerances given to CVODE (CVodeSStolerances clears CVODE's error-weight data until its next
    // initial setup, so it is called only when they change, and then CVODE is re-initialised).
    double rtol = 0, atol = 0;
    CvodeHandles h;  // last member: destroyed first, while the data above still exists

    Workspace(const CvodeSettings& s, double t0);
    Workspace(const Workspace&) = delete;
    Workspace& operator=(const Workspace&) = delete;

    void check(int flag, const char* call) {
        if (flag >= 0) return;
        std::string m = std::string("CVODE ") + call + " failed (" + flag_name(flag) + ")";
        if (!error.empty()) m += ": " + error;
        throw CvodeError(m);
    }

    static int rhs(realtype, N_Vector y, N_Vector ydot, void* data) {
        auto* w = static_cast<Workspace*>(data);
        const double* p = N_VGetArrayPointer(y);
        double* d = N_VGetArrayPointer(ydot);
        w->ode.rhs(p, d);
        // Non-finite: recoverable, CVODE retries with a smaller step (and fails if it persists).
        return std::isfinite(d[0]) && std::isfinite(d[1]) ? 0 : 1;
    }

    static int jac(realtype, N_Vector y, N_Vector, SUNMatrix J, void* data, N_Vector, N_Vector, N_Vector) {
        auto* w = static_cast<Workspace*>(data);
        double j[4];
        w->ode.jacobian(N_VGetArrayPointer(y), j);
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
        } catch (...) {
        }
    }
};

CvodeIntegrator::Workspace::Workspace(const CvodeSettings& s, double t0) : built_for(s) {
    // On a throw, h's destructor frees whatever was made so far.
    if (SUNContext_Create(nullptr, &h.ctx) != 0 || h.ctx == nullptr) throw CvodeError("SUNContext_Create failed");
    h.y = N_VNew_Serial(2, h.ctx);
    if (h.y == nullptr) throw CvodeError("N_VNew_Serial failed");
    N_VConst(0.0, h.y);
    h.mem = CVodeCreate(s.method == CvodeMethod::bdf ? CV_BDF : CV_ADAMS, h.ctx);
    if (h.mem == nullptr) throw CvodeError("CVodeCreate failed");
    check(CVodeSetErrHandlerFn(h.mem, &Workspace::handler, this), "CVodeSetErrHandlerFn");
    check(CVodeInit(h.mem, &Workspace::rhs, t0, h.y), "CVodeInit");
    check(CVodeSetUserData(h.mem, this), "CVodeSetUserData");
    check(CVodeSStolerances(h.mem, s.rtol, s.atol), "CVodeSStolerances");
    rtol = s.rtol;
    atol = s.atol;
    if (s.nonlinear == CvodeNonlinear::fixed_point) {
        h.nls = SUNNonlinSol_FixedPoint(h.y, 0, h.ctx);
        if (h.nls == nullptr) throw CvodeError("SUNNonlinSol_FixedPoint failed");
        check(CVodeSetNonlinearSolver(h.mem, h.nls), "CVodeSetNonlinearSolver");
    } else {
        h.A = SUNDenseMatrix(2, 2, h.ctx);
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
    : settings_(o.settings_), state_(o.state_), stats_(o.stats_), warnings_(o.warnings_) {}

CvodeIntegrator& CvodeIntegrator::operator=(const CvodeIntegrator& o) {
    if (this == &o) return *this;
    settings_ = o.settings_;
    state_ = o.state_;
    stats_ = o.stats_;
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
    warnings_.clear();
}

double CvodeIntegrator::initial_step(const DqFluxOde& ode, double span) const {
    switch (settings_.init_step) {
        case CvodeInitStep::estimate: return 0.0;
        case CvodeInitStep::previous_last:
        case CvodeInitStep::previous_next: return std::min(state_.h_next, span);
        case CvodeInitStep::curvature: break;
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

CvodeIntegrator::Workspace& CvodeIntegrator::workspace(double t0) {
    if (!ws_ || !ws_->built_for.same_structure(settings_)) {
        ws_.reset();
        ws_ = std::make_unique<Workspace>(settings_, t0);
    }
    return *ws_;
}

void CvodeIntegrator::advance(const DqFluxOde& ode, double t_end) {
    const double t0 = state_.t, span = t_end - t0;
    if (!(span > 0) || !std::isfinite(span))
        throw CvodeError("CvodeIntegrator::advance: t_end = " + number(t_end) + " is not after t = " + number(t0));
    if (!(settings_.rtol > 0) || !(settings_.atol > 0))
        throw CvodeError("CvodeIntegrator: rtol and atol must be > 0");

    // An interval CVODE cannot resolve in floating point ("tout too close to t0"): one Euler
    // step, exact to far below any tolerance.
    if (span <= 64 * std::numeric_limits<double>::epsilon() * std::max(std::abs(t0), std::abs(t_end))) {
        double d[2];
        ode.rhs(state_.psi, d);
        CvodeState s = state_;
        s.t = t_end;
        s.psi[0] += span * d[0];
        s.psi[1] += span * d[1];
        if (!std::isfinite(s.psi[0]) || !std::isfinite(s.psi[1]))
            throw CvodeError("the right-hand side is not finite at t = " + number(t0));
        state_ = s;
        stats_ = CvodeStats{};
        warnings_.clear();
        return;
    }

    Workspace& w = workspace(t0);
    w.ode = ode;
    w.error.clear();
    w.warning.clear();
    double* y = N_VGetArrayPointer(w.h.y);
    void* mem = w.h.mem;
    const bool new_tolerances = w.rtol != settings_.rtol || w.atol != settings_.atol;
    const bool resume = !settings_.reinit_each_step && w.live && !new_tolerances && w.live_t == t0 &&
                        w.live_psi[0] == state_.psi[0] && w.live_psi[1] == state_.psi[1];
    long steps0 = 0, rhs0 = 0, etf0 = 0, nni0 = 0, ncf0 = 0;
    try {
        if (resume) {
            CVodeGetNumSteps(mem, &steps0);
            CVodeGetNumRhsEvals(mem, &rhs0);
            CVodeGetNumErrTestFails(mem, &etf0);
            CVodeGetNumNonlinSolvIters(mem, &nni0);
            CVodeGetNumNonlinSolvConvFails(mem, &ncf0);
        } else {
            y[0] = state_.psi[0];
            y[1] = state_.psi[1];
            w.live = false;
            w.check(CVodeReInit(mem, t0, w.h.y), "CVodeReInit");
            w.check(CVodeSetInitStep(mem, initial_step(ode, span)), "CVodeSetInitStep");
        }
        if (new_tolerances) {
            w.rtol = w.atol = 0;  // unknown until the call succeeds
            w.check(CVodeSStolerances(mem, settings_.rtol, settings_.atol), "CVodeSStolerances");
            w.rtol = settings_.rtol;
            w.atol = settings_.atol;
        }
        w.check(CVodeSetMaxNumSteps(mem, settings_.max_steps), "CVodeSetMaxNumSteps");
        w.check(CVodeSetStopTime(mem, t_end), "CVodeSetStopTime");
        double t_ret = t0;
        const int flag = CVode(mem, t_end, w.h.y, &t_ret, CV_NORMAL);
        if (flag < 0) {
            std::string m = "CVODE failed between t = " + number(t0) + " s and " + number(t_end) + " s (" +
                            flag_name(flag) + ")";
            if (!w.error.empty()) m += ": " + w.error;
            throw CvodeError(m);
        }
        if (!std::isfinite(y[0]) || !std::isfinite(y[1]))
            throw CvodeError("CVODE returned non-finite flux linkages at t = " + number(t_end));
    } catch (...) {
        w.live = false;
        throw;
    }

    CvodeStats st;
    CVodeGetNumSteps(mem, &st.steps);
    CVodeGetNumRhsEvals(mem, &st.rhs_evals);
    CVodeGetNumErrTestFails(mem, &st.error_test_fails);
    CVodeGetNumNonlinSolvIters(mem, &st.nonlinear_iterations);
    CVodeGetNumNonlinSolvConvFails(mem, &st.nonlinear_failures);
    CVodeGetLastOrder(mem, &st.last_order);
    CVodeGetLastStep(mem, &st.last_step);
    st.steps -= steps0;
    st.rhs_evals -= rhs0;
    st.error_test_fails -= etf0;
    st.nonlinear_iterations -= nni0;
    st.nonlinear_failures -= ncf0;

    // Commit.
    state_.t = t_end;
    state_.psi[0] = y[0];
    state_.psi[1] = y[1];
    double h_next = st.last_step;
    if (settings_.init_step == CvodeInitStep::previous_next) CVodeGetCurrentStep(mem, &h_next);
    state_.h_next = h_next > 0 && std::isfinite(h_next) ? h_next : 0.0;
    stats_ = st;
    warnings_ = w.warning;
    w.live = true;
    w.live_t = t_end;
    w.live_psi[0] = y[0];
    w.live_psi[1] = y[1];
}

}  // namespace ipmsm
