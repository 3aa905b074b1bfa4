#include "freewheel_integrator.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "cvode_handles.hpp"
#include "explicit_steps.hpp"
#include "inverter_state.hpp"
#include "linearised_step.hpp"

namespace ipmsm {

namespace {

// y: psi_d, psi_q, the step integrals, int |i|, int |i|^2.
constexpr int kY = 2 + StepIntegrands::count + 2;
constexpr int kAbsI = 2 + StepIntegrands::count, kAbsI2 = kAbsI + 1;
// Segments (between roots) per call before the call is refused: each root ends one, and a
// trajectory has at most a few (a false root, an arming, a block).
constexpr int kMaxSegments = 64;
// A falling root of g = i . n_b is the current's zero when the flux there is within this many
// tolerances of psi_0 (|L_0 i| <= kZeroTolerances (rtol |psi_0| + atol)); a turn of the current
// by 90 degrees away from n_b crosses g = 0 at amperes.
constexpr double kZeroTolerances = 100.0;
// Currents below this fraction of the map's current scale are i = 0 for the bridge's direction:
// the inverse map returns rounding-sized currents of any direction at psi_0.
constexpr double kZeroCurrent = 1e-9;
// The bridge's voltage is continued past a zero of g_j (the crossing of the line i = s n_j) only
// where |i| is below this fraction of the current scale: a current crossing that line at amperes
// (a false root) keeps the bridge's own voltage.
constexpr double kContinuedCurrent = 1e-3;

// The explicit steps of a conducting call give up where the current falls below this fraction of
// its value at the call's start (or below the continued-current bound above): a current heading
// for zero is left to CVODE's root finding.
constexpr double kConductingFraction = 0.5;
// The shortest linearised step, as a fraction of the call (ConductingStep: CVODE below it).
constexpr double kMinSpan = 1.0 / 16.0;

// The conducting bridge's linearised step (a Problem of explicit_steps.hpp; MATH.md, "The
// inverter's safe states"): the dq equations with the bridge's voltage u(i) = -k i/|i|,
// linearised at the call's start psi0, i0 = i(psi0):
//     f(psi) = f0 + A (psi - psi0) + N(psi),   A = (D0 - R I) G0 + omega J,
//     D0 = du/di(i0) = -(k/|i0|) (I - e e^T), e = i0/|i0|,
//     N = u(i) - u0 - D0 (i_lin - i0) - R (i - i_lin),   i_lin = i0 + G0 (psi - psi0),
// the linear part's flow exact (linear_flow.hpp): the bridge's resistance k/|i| across the
// current, the stiff part, is in A. Valid while the current stays away from zero and from the
// lines i = s n_j where the root functions change sign (within()); elsewhere CVODE integrates
// the call with its root finding.
struct ConductingStep {
    static constexpr int kY = 2 + StepIntegrands::count + 2;  // kY above
    DqFluxOde ode;
    double k = 0;
    Linearisation lin;
    double u0[2] = {0, 0}, D0[4] = {0, 0, 0, 0};
    const StepIntegrands* integrands = nullptr;
    const BridgeDirections* dirs = nullptr;
    bool positive[4] = {};  // g_j = i . n_j > 0 at the start
    double r_min = 0;       // A: the current's smallest magnitude within()

    // False where the start has no finite currents, is too close to zero, or the linearisation is
    // too stiff for the step (linearised_step.hpp: kStiffLimit).
    bool linearise(const double* psi, const InverseFluxPoint& c, double r_continue, double h) {
        const double r = std::hypot(c.i_d, c.i_q);
        if (!(r > r_continue) || !std::isfinite(r)) return false;
        const double ed = c.i_d / r, eq = c.i_q / r, a = -k / r;
        u0[0] = -k * ed;
        u0[1] = -k * eq;
        D0[0] = a * (1.0 - ed * ed);
        D0[1] = D0[2] = -a * ed * eq;
        D0[3] = a * (1.0 - eq * eq);
        const double R = ode.R, w = ode.omega;
        const double M[4] = {D0[0] - R, D0[1], D0[2], D0[3] - R};
        const double A[4] = {M[0] * c.G_dd + M[1] * c.G_qd, M[0] * c.G_dq + M[1] * c.G_qq + w,
                             M[2] * c.G_dd + M[3] * c.G_qd - w, M[2] * c.G_dq + M[3] * c.G_qq};
        const double f0[2] = {u0[0] - R * c.i_d + w * psi[1], u0[1] - R * c.i_q - w * psi[0]};
        if (!std::isfinite(f0[0] + f0[1] + A[0] + A[1] + A[2] + A[3])) return false;
        lin.set(psi, c, f0, A);
        for (int j = 0; j < dirs->n_decay; ++j)
            positive[j] = c.i_d * dirs->decay[j][0] + c.i_q * dirs->decay[j][1] > 0.0;
        r_min = std::max(r_continue, kConductingFraction * r);
        return lin.flow.max_decay() * h <= kStiffLimit;
    }

    void start_derivative(double* d) const {
        d[0] = d[1] = 0.0;
        const InverseFluxPoint c0{lin.i0[0], lin.i0[1], lin.G0[0], lin.G0[1], lin.G0[2], lin.G0[3]};
        integrands_at(lin.psi0, c0, d);
    }

    void linearised_rhs(const FlowAt& F, const double* y, double* d, double* psi, InverseFluxPoint& c) const {
        lin.psi_at(F, y, psi);
        double i_lin[2];
        lin.predicted_currents(psi, i_lin);
        c = ode.currents_near(psi[0], psi[1], i_lin[0], i_lin[1]);
        const double r = std::hypot(c.i_d, c.i_q);
        const double di[2] = {i_lin[0] - lin.i0[0], i_lin[1] - lin.i0[1]};
        const double n0 = (-k * c.i_d / r - u0[0]) - (D0[0] * di[0] + D0[1] * di[1]) - ode.R * (c.i_d - i_lin[0]);
        const double n1 = (-k * c.i_q / r - u0[1]) - (D0[2] * di[0] + D0[3] * di[1]) - ode.R * (c.i_q - i_lin[1]);
        d[0] = F.E_inv[0] * n0 + F.E_inv[1] * n1;
        d[1] = F.E_inv[2] * n0 + F.E_inv[3] * n1;
        integrands_at(psi, c, d);
    }

    // The step integrals' integrands (y's components from 2) at psi with its currents c, as
    // Workspace::rhs.
    void integrands_at(const double* psi, const InverseFluxPoint& c, double* d) const {
        const double r = std::hypot(c.i_d, c.i_q);
        DqFluxOde o = ode;
        o.u_d = -k * c.i_d / r;
        o.u_q = -k * c.i_q / r;
        integrands->eval(o, psi[0], psi[1], c.i_d, c.i_q, d + 2);
        d[kAbsI] = r;
        d[kAbsI2] = r * r;
    }

    bool within(const InverseFluxPoint& c) const {
        if (!(std::hypot(c.i_d, c.i_q) >= r_min)) return false;
        for (int j = 0; j < dirs->n_decay; ++j)
            if ((c.i_d * dirs->decay[j][0] + c.i_q * dirs->decay[j][1] > 0.0) != positive[j]) return false;
        return true;
    }
};

std::string number(double x) {
    char b[32];
    std::snprintf(b, sizeof b, "%.17g", x);
    return b;
}

}  // namespace

struct FreewheelIntegrator::Workspace {
    DqFluxOde ode;
    const StepIntegrands* integrands = nullptr;
    double k = 0;
    BridgeDirections dirs;    // the directions a current reaches zero along (inverter_state.hpp)
    bool dirs_valid = false;  // ... computed for e_0, k, L_0 = dirs_for
    double dirs_for[7] = {};
    double n_zero[2] = {0, 0};  // the bridge's direction at i = 0 exactly (the onset direction)
    bool armed[4] = {};         // falling zero of g_j wanted; the voltage continued past it (above)
    double r_zero = 0;          // A: a current below this is i = 0 (the bridge's direction n_zero)
    double r_continue = 0;      // A: the voltage is continued past a zero only below this current
    double seed[2] = {0, 0};    // the last currents: the next Newton's start
    std::string error;
    CvodeHandles h;

    Workspace() {
        if (SUNContext_Create(nullptr, &h.ctx) != 0 || h.ctx == nullptr) throw CvodeError("SUNContext_Create failed");
        h.y = N_VNew_Serial(kY, h.ctx);
        h.atol = N_VNew_Serial(kY, h.ctx);
        if (h.y == nullptr || h.atol == nullptr) throw CvodeError("N_VNew_Serial failed");
        N_VConst(0.0, h.y);
        N_VConst(1.0, h.atol);
        h.mem = CVodeCreate(CV_BDF, h.ctx);
        if (h.mem == nullptr) throw CvodeError("CVodeCreate failed");
        check(CVodeSetErrHandlerFn(h.mem, &Workspace::handler, this), "CVodeSetErrHandlerFn");
        check(CVodeInit(h.mem, &Workspace::rhs, 0.0, h.y), "CVodeInit");
        check(CVodeSetUserData(h.mem, this), "CVodeSetUserData");
        check(CVodeSVtolerances(h.mem, 1e-6, h.atol), "CVodeSVtolerances");
        h.A = SUNDenseMatrix(kY, kY, h.ctx);
        if (h.A == nullptr) throw CvodeError("SUNDenseMatrix failed");
        h.ls = SUNLinSol_Dense(h.y, h.A, h.ctx);
        if (h.ls == nullptr) throw CvodeError("SUNLinSol_Dense failed");
        check(CVodeSetLinearSolver(h.mem, h.ls, h.A), "CVodeSetLinearSolver");
        check(CVodeSetJacFn(h.mem, &Workspace::jac), "CVodeSetJacFn");
    }
    Workspace(const Workspace&) = delete;
    Workspace& operator=(const Workspace&) = delete;

    void check(int flag, const char* call) {
        if (flag >= 0) return;
        char* name = CVodeGetReturnFlagName(flag);
        std::string m = std::string("CVODE ") + call + " failed (" + (name != nullptr ? name : "?") + ")";
        std::free(name);
        if (!error.empty()) m += ": " + error;
        throw CvodeError(m);
    }

    InverseFluxPoint currents(const double* psi) {
        const InverseFluxPoint c = ode.currents_near(psi[0], psi[1], seed[0], seed[1]);
        if (std::isfinite(c.i_d) && std::isfinite(c.i_q)) {
            seed[0] = c.i_d;
            seed[1] = c.i_q;
        }
        return c;
    }

    // The bridge's voltage direction at the currents i (|i| = r), continued past the zero in an
    // armed segment; sigma its sign relative to i/|i|.
    void direction(const InverseFluxPoint& c, double r, double* n, double& sigma) const {
        if (r <= r_zero) {
            n[0] = n_zero[0];
            n[1] = n_zero[1];
            sigma = 1.0;
            return;
        }
        sigma = 1.0;
        if (r < r_continue)
            for (int j = 0; j < dirs.n_decay; ++j)
                if (armed[j] && c.i_d * dirs.decay[j][0] + c.i_q * dirs.decay[j][1] < 0.0) sigma = -1.0;
        n[0] = sigma * c.i_d / r;
        n[1] = sigma * c.i_q / r;
    }

    static int rhs(realtype, N_Vector y, N_Vector ydot, void* data) {
        auto* w = static_cast<Workspace*>(data);
        const double* p = N_VGetArrayPointer(y);
        double* d = N_VGetArrayPointer(ydot);
        const InverseFluxPoint c = w->currents(p);
        const double r = std::hypot(c.i_d, c.i_q);
        double n[2], sigma;
        w->direction(c, r, n, sigma);
        DqFluxOde o = w->ode;
        o.u_d = -w->k * n[0];
        o.u_q = -w->k * n[1];
        d[0] = o.u_d - o.R * c.i_d + o.omega * p[1];
        d[1] = o.u_q - o.R * c.i_q - o.omega * p[0];
        w->integrands->eval(o, p[0], p[1], c.i_d, c.i_q, d + 2);
        d[kAbsI] = r;
        d[kAbsI2] = r * r;
        double sum = 0.0;
        for (int k = 0; k < kY; ++k) sum += d[k];
        return std::isfinite(sum) ? 0 : 1;  // non-finite: CVODE retries with a smaller step
    }

    // d f / d psi = (D_u - R I) G + omega J, D_u = d u / d i = -k sigma (I - i i^T / r^2) / r.
    static int jac(realtype, N_Vector y, N_Vector, SUNMatrix J, void* data, N_Vector, N_Vector, N_Vector) {
        auto* w = static_cast<Workspace*>(data);
        const double* p = N_VGetArrayPointer(y);
        const InverseFluxPoint c = w->currents(p);
        const double r = std::hypot(c.i_d, c.i_q);
        double n[2], sigma;
        w->direction(c, r, n, sigma);
        double D[4] = {0, 0, 0, 0};
        if (r > w->r_zero) {
            const double a = -w->k * sigma / r, ed = c.i_d / r, eq = c.i_q / r;
            D[0] = a * (1.0 - ed * ed);
            D[1] = D[2] = -a * ed * eq;
            D[3] = a * (1.0 - eq * eq);
        }
        const double R = w->ode.R;
        D[0] -= R;
        D[3] -= R;
        const double G[4] = {c.G_dd, c.G_dq, c.G_qd, c.G_qq};
        SUNMatZero(J);
        SM_ELEMENT_D(J, 0, 0) = D[0] * G[0] + D[1] * G[2];
        SM_ELEMENT_D(J, 0, 1) = D[0] * G[1] + D[1] * G[3] + w->ode.omega;
        SM_ELEMENT_D(J, 1, 0) = D[2] * G[0] + D[3] * G[2] - w->ode.omega;
        SM_ELEMENT_D(J, 1, 1) = D[2] * G[1] + D[3] * G[3];
        const double s = SM_ELEMENT_D(J, 0, 0) + SM_ELEMENT_D(J, 0, 1) + SM_ELEMENT_D(J, 1, 0) + SM_ELEMENT_D(J, 1, 1);
        return std::isfinite(s) ? 0 : 1;
    }

    static int root(realtype, N_Vector y, realtype* g, void* data) {
        auto* w = static_cast<Workspace*>(data);
        const InverseFluxPoint c = w->currents(N_VGetArrayPointer(y));
        for (int j = 0; j < w->dirs.n_decay; ++j) g[j] = c.i_d * w->dirs.decay[j][0] + c.i_q * w->dirs.decay[j][1];
        return std::isfinite(c.i_d + c.i_q) ? 0 : 1;
    }

    static void handler(int code, const char* module, const char* function, char* msg, void* data) {
        auto* w = static_cast<Workspace*>(data);
        if (code == CV_WARNING) return;
        try {
            if (!w->error.empty()) w->error += "; ";
            w->error += std::string(module != nullptr ? module : "CVODE") + "/" +
                        (function != nullptr ? function : "?") + ": " + (msg != nullptr ? msg : "");
        } catch (...) {}
    }
};

FreewheelIntegrator::FreewheelIntegrator() = default;
FreewheelIntegrator::~FreewheelIntegrator() = default;
FreewheelIntegrator::FreewheelIntegrator(const FreewheelIntegrator&) {}
FreewheelIntegrator& FreewheelIntegrator::operator=(const FreewheelIntegrator&) { return *this; }
FreewheelIntegrator::FreewheelIntegrator(FreewheelIntegrator&&) noexcept = default;
FreewheelIntegrator& FreewheelIntegrator::operator=(FreewheelIntegrator&&) noexcept = default;

FreewheelStep FreewheelIntegrator::advance(const DqFluxOde& ode, double k, const StepIntegrands& integrands,
                                           const CvodeSettings& s, double h, const double* psi, bool blocked,
                                           const double* i_seed, double h_start) {
    if (!(h > 0) || !std::isfinite(h)) throw CvodeError("freewheeling: the step h = " + number(h) + " s is not > 0");
    if (!(k > 0) || !std::isfinite(k))
        throw CvodeError("freewheeling: the bridge's voltage 2 u_dc / pi = " + number(k) + " V is not > 0");
    // psi_0, the back-EMF there and the inductance at zero current (inverter_state.hpp).
    const FluxPoint z = ode.inverse->forward_eval(0.0, 0.0);
    const double psi0[2] = {z.psi_d + ode.delta_psi_m, z.psi_q};
    const double e0[2] = {ode.omega * psi0[1], -ode.omega * psi0[0]};
    const double L0[4] = {z.L_dd, z.L_dq, z.L_qd, z.L_qq};
    // |e_0| <= k: no onset (inverter_state.hpp); the directions only where a current flows
    const bool onset = std::hypot(e0[0], e0[1]) > k;
    FreewheelStep out;
    const IronLossModel& fe = integrands.fe;
    auto blocked_for = [&](double span) {  // i = 0, psi = psi_0: only the iron loss of the magnet's flux
        out.integrals[StepIntegrands::P_fe] += span * fe.power(integrands.pole_pairs, integrands.w_m, psi0[0], psi0[1]);
    };
    double start[2] = {psi[0], psi[1]};
    // A current whose flux is within the zero tolerance of psi_0 (the one a root's zero is accepted
    // with, below) is i = 0, as exactly zero currents are: its direction is rounding, and the
    // bridge's resistance k/|i| would make it a stiffness no step resolves. It starts as the bridge
    // does from i = 0: blocked below the onset, conducting along n_on above it (MATH.md, "Onset and
    // blocking, exactly").
    const double zero_tol = kZeroTolerances * (s.rtol * std::hypot(psi0[0], psi0[1]) + s.atol);
    const bool at_zero = blocked || std::hypot(psi[0] - psi0[0], psi[1] - psi0[1]) <= zero_tol;
    if (at_zero) {
        if (!onset) {
            blocked_for(h);
            out.psi[0] = psi0[0], out.psi[1] = psi0[1];
            out.blocked = true;
            return out;
        }
        start[0] = psi0[0], start[1] = psi0[1];  // conduction starts from i = 0 along n_on
        if (blocked) ++out.switchings;
    }

    if (!ws_) ws_ = std::make_unique<Workspace>();
    Workspace& w = *ws_;
    // the directions are a function of e_0, k and L_0 alone: computed again only when they change
    if (!w.dirs_valid || w.dirs_for[0] != e0[0] || w.dirs_for[1] != e0[1] || w.dirs_for[2] != k ||
        !std::equal(L0, L0 + 4, w.dirs_for + 3)) {
        w.dirs = bridge_directions(e0, k, L0);
        w.dirs_for[0] = e0[0], w.dirs_for[1] = e0[1], w.dirs_for[2] = k;
        std::copy(L0, L0 + 4, w.dirs_for + 3);
        w.dirs_valid = true;
    }
    const BridgeDirections& dirs = w.dirs;
    w.ode = ode;
    w.integrands = &integrands;
    w.k = k;
    w.n_zero[0] = onset ? dirs.onset[0] : 0.0;
    w.n_zero[1] = onset ? dirs.onset[1] : 0.0;
    w.seed[0] = at_zero ? 0.0 : i_seed[0];
    w.seed[1] = at_zero ? 0.0 : i_seed[1];
    w.r_zero = kZeroCurrent * s.current_scale;
    w.r_continue = kContinuedCurrent * s.current_scale;
    w.error.clear();
    void* mem = w.h.mem;
    const double energy = 1.5 * s.atol * s.current_scale;
    double atol[kY];
    atol[0] = atol[1] = s.atol;
    atol[2 + StepIntegrands::P_elec] = atol[2 + StepIntegrands::P_cu] = atol[2 + StepIntegrands::P_fe] = energy;
    atol[2 + StepIntegrands::T_e] = energy * integrands.pole_pairs * h;
    atol[kAbsI] = energy / (1.5 * k);  // the DC charge's share of the energy tolerance
    atol[kAbsI2] = atol[kAbsI] * s.current_scale;
    std::copy(atol, atol + kY, N_VGetArrayPointer(w.h.atol));
    // y: the flux linkages and the step integrals so far, at t.
    double* y = N_VGetArrayPointer(w.h.y);
    std::fill(y, y + kY, 0.0);
    y[0] = start[0];
    y[1] = start[1];
    double t = 0.0;
    // Conducting from a current away from zero: linearised steps (ConductingStep above) with their
    // explicit steps, as the switching path's, each over the rest of the call, or where one gives
    // up over half its span (linearised afresh at its start), down to kMinSpan of the call; CVODE
    // integrates the rest of the call from where they stopped.
    if (!at_zero && s.linearised && s.explicit_first) {
        ConductingStep p;
        p.ode = ode;
        p.k = k;
        p.integrands = &integrands;
        p.dirs = &dirs;
        InverseFluxPoint c = ode.currents_near(start[0], start[1], i_seed[0], i_seed[1]);
        double span = h;
        while (true) {
            const bool last = span >= h - t;
            if (last) span = h - t;
            double y_end[kY], psi_end[2];
            InverseFluxPoint c_end;
            CvodeStats st;
            const bool ok = p.linearise(y, c, w.r_continue, span) &&
                            explicit_steps(p, span, s.rtol, atol, s.explicit_attempts, y_end, psi_end, c_end, st);
            out.steps += st.steps;
            out.rhs_evals += st.rhs_evals;
            if (!ok) {
                if (span <= kMinSpan * h) break;
                span *= 0.5;
                continue;
            }
            y[0] = psi_end[0], y[1] = psi_end[1];
            for (int q = 2; q < kY; ++q) y[q] += y_end[q];
            c = c_end;
            out.h_last = st.last_step;
            if (last) {
                for (int q = 0; q < StepIntegrands::count; ++q) out.integrals[q] = y[2 + q];
                out.I_integral = y[kAbsI];
                out.I2_integral = y[kAbsI2];
                out.psi[0] = y[0], out.psi[1] = y[1];
                out.c = c;
                return out;
            }
            t += span;
            span *= 2.0;
        }
        if (std::isfinite(c.i_d + c.i_q)) w.seed[0] = c.i_d, w.seed[1] = c.i_q;
    }
    // arm every direction the current points along (g_j > 0) at a segment's start
    auto arm = [&]() {
        const InverseFluxPoint c = w.currents(y);
        for (int j = 0; j < dirs.n_decay; ++j)
            w.armed[j] = c.i_d * dirs.decay[j][0] + c.i_q * dirs.decay[j][1] > w.r_zero;
    };
    arm();
    const int n_roots = dirs.n_decay;
    w.check(CVodeRootInit(mem, n_roots, n_roots > 0 ? &Workspace::root : nullptr), "CVodeRootInit");
    for (int segment = 0;; ++segment) {
        if (segment >= kMaxSegments)
            throw CvodeError("freewheeling: more than " + std::to_string(kMaxSegments) +
                             " roots of the bridge's switching functions in one step");
        w.check(CVodeReInit(mem, t, w.h.y), "CVodeReInit");
        w.check(CVodeSVtolerances(mem, s.rtol, w.h.atol), "CVodeSVtolerances");
        w.check(CVodeSetMaxNumSteps(mem, s.max_steps), "CVodeSetMaxNumSteps");
        w.check(CVodeSetStopTime(mem, h), "CVodeSetStopTime");
        w.check(CVodeSetInitStep(mem, segment == 0 && h_start > 0.0 ? std::min(h_start, h - t) : 0.0),
                "CVodeSetInitStep");
        if (n_roots > 0) {
            int direction[4];
            for (int j = 0; j < n_roots; ++j) direction[j] = w.armed[j] ? -1 : 1;
            w.check(CVodeSetRootDirection(mem, direction), "CVodeSetRootDirection");
            w.check(CVodeSetNoInactiveRootWarn(mem), "CVodeSetNoInactiveRootWarn");
        }
        double t_ret = t;
        const int flag = CVode(mem, h, w.h.y, &t_ret, CV_NORMAL);
        long nst = 0, nfe = 0;
        CVodeGetLastStep(mem, &out.h_last);
        CVodeGetNumSteps(mem, &nst);
        CVodeGetNumRhsEvals(mem, &nfe);
        out.steps += nst;
        out.rhs_evals += nfe;
        if (flag < 0) {
            std::string m = "CVODE failed while freewheeling (" + number(h) + " s step)";
            char* name = CVodeGetReturnFlagName(flag);
            m += std::string(" (") + (name != nullptr ? name : "?") + ")";
            std::free(name);
            if (!w.error.empty()) m += ": " + w.error;
            throw CvodeError(m);
        }
        t = t_ret;
        if (flag != CV_ROOT_RETURN) break;  // the end of the step
        int found[4] = {0, 0, 0, 0};
        w.check(CVodeGetRootInfo(mem, found), "CVodeGetRootInfo");
        bool zero = false;
        for (int j = 0; j < n_roots; ++j) {
            if (found[j] == 0) continue;
            if (!w.armed[j]) {  // g_j rose through zero: from here a zero of the current along n_j is watched
                w.armed[j] = true;
                continue;
            }
            const InverseFluxPoint c = w.currents(y);
            const double dpsi[2] = {L0[0] * c.i_d + L0[1] * c.i_q, L0[2] * c.i_d + L0[3] * c.i_q};
            if (std::hypot(dpsi[0], dpsi[1]) <= zero_tol)
                zero = true;
            else
                w.armed[j] = false;  // the current crossed the line i = s n_j away from zero
        }
        if (!zero) continue;
        y[0] = psi0[0];  // i = 0 exactly
        y[1] = psi0[1];
        w.seed[0] = w.seed[1] = 0.0;
        if (onset) {  // the current passes zero and grows again along the onset direction
            for (int j = 0; j < n_roots; ++j) w.armed[j] = false;
            continue;
        }
        // The bridge blocks: i = 0, psi = psi_0 for the rest of the step.
        for (int q = 0; q < StepIntegrands::count; ++q) out.integrals[q] = y[2 + q];
        out.I_integral = y[kAbsI];
        out.I2_integral = y[kAbsI2];
        blocked_for(h - t);
        out.psi[0] = psi0[0], out.psi[1] = psi0[1];
        out.blocked = true;
        ++out.switchings;
        return out;
    }
    for (int q = 0; q < StepIntegrands::count; ++q) out.integrals[q] = y[2 + q];
    out.I_integral = y[kAbsI];
    out.I2_integral = y[kAbsI2];
    out.psi[0] = y[0], out.psi[1] = y[1];
    out.c = w.currents(y);
    if (!std::isfinite(out.psi[0] + out.psi[1] + out.c.i_d + out.c.i_q))
        throw CvodeError("freewheeling: non-finite flux linkages or currents at the end of the step");
    // Below the onset, a call ending within the zero tolerance of psi_0 (its zero not yet crossed)
    // has brought the current to zero: the next call would start there as from i = 0, blocked. The
    // bridge blocks at this call's end, so that the block is counted where it happens.
    if (!onset && std::hypot(y[0] - psi0[0], y[1] - psi0[1]) <= zero_tol) {
        out.psi[0] = psi0[0], out.psi[1] = psi0[1];
        out.c = InverseFluxPoint{};
        out.blocked = true;
        ++out.switchings;
    }
    return out;
}

}  // namespace ipmsm
