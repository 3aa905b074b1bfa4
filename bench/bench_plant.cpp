// Cost of one 100 us communication step of the IpmsmPlant at top speed under load, for the
// CVODE settings the FMU uses and for the alternatives (Adams vs BDF, functional iteration vs
// Newton, tolerances, initial step, order limit, and CVODE's defaults).
//
// 1. Record: the controller and the plant in closed loop at 12 000 r/min, their models coupled
//    in C++ on the drive's coupling description (fmu_src/coupling/coupled_models.hpp, as the
//    IpmsmDrive couples them; the same sequence of calls as two FMUs under a master), 100 us:
//    the torque command is held at 60 or 80 N.m (about the maximum there: the regulator's small
//    corrections each step), ramps 20 -> 80 N.m, or alternates 80 / 40 N.m every 10 ms (current
//    transients). The plant's voltages of every step are recorded.
// 2. Replay the recorded voltages through CvodeIntegrator (plant/cvode_integrator.hpp) with each
//    setting: microseconds per step (best of several rounds), CVODE steps and RHS evaluations per
//    step, and the largest current error against a reference run (Adams, rtol 1e-12).
// 3. The same replay through the plant FMU's fmi2SetReal + fmi2DoStep (the whole FMI call, with
//    the glue's per-step copy of the model; the FMU dlopened by tests/cpp/fmu_binary.hpp), for
//    the FMU's default settings and for cvode_method 2.
//
// Usage: bench_plant [rounds] [flux_map.csv]. The plant FMU is found next to this executable
// (../fmu/). A flux map (e.g. a strongly saturating one from tools/saturating_map.py, same pole
// pairs and R_s as the default motor) replaces the default one in both models and the replay.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "controller/controller_model.hpp"
#include "coupling/coupled_models.hpp"
#include "coupling/drive_coupling_text.hpp"
#include "cvode_integrator.hpp"
#include "fmi2Functions.h"
#include "fmu_binary.hpp"
#include "machine/flux_map.hpp"
#include "machine/inverse_flux_map.hpp"
#include "plant_model.hpp"
#include "source_tree.hpp"

using namespace ipmsm;
namespace fs = std::filesystem;

namespace {

constexpr double kH = 1e-4;
constexpr double kTopSpeed = 1256.6370614359173;  // rad/s, 12 000 r/min
constexpr int kPolePairs = 4;
constexpr double kRs = 0.012;

void quiet_logger(fmi2ComponentEnvironment, fmi2String, fmi2Status status, fmi2String, fmi2String message, ...) {
    if (status < fmi2Error) return;
    char buf[4096];
    va_list ap;
    va_start(ap, message);
    std::vsnprintf(buf, sizeof buf, message, ap);
    va_end(ap);
    std::fprintf(stderr, "FMU: %s\n", buf);
}

// One unzipped FMU: its model description and its binary's functions (fmu_binary.hpp).
struct Fmu {
    std::string dir;
    fmu_binary::Description d;
    fmu_binary::Functions fn;
    fmi2CallbackFunctions cb{quiet_logger, nullptr, nullptr, nullptr, nullptr};
    std::string flux_map;  // "" = the FMU's default map

    Fmu(const fs::path& unzipped, const char* id) : dir(unzipped.string()), d(fmu_binary::read_description(dir)) {
        fn.open_or_exit(fmu_binary::library_path(dir, id), "build the FMUs first");
    }
    // Instantiate, set Real and Integer parameters, initialise.
    fmi2Component make(const char* name, const std::map<std::string, double>& reals,
                       const std::map<std::string, int>& ints = {}) {
        const std::string res = "file://" + dir + "/resources";
        fmi2Component c =
            fn.fmi2Instantiate(name, fmi2CoSimulation, d.guid.c_str(), res.c_str(), &cb, fmi2False, fmi2False);
        if (c == nullptr) std::exit(3);
        ok(fn.fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
        ok(fn.fmi2EnterInitializationMode(c));
        if (!flux_map.empty()) {
            const fmi2ValueReference r = d.vr.at("flux_map");
            const fmi2String v = flux_map.c_str();
            ok(fn.fmi2SetString(c, &r, 1, &v));
        }
        for (const auto& [n, v] : reals) set(c, n, v);
        for (const auto& [n, v] : ints) {
            const fmi2ValueReference r = d.vr.at(n);
            const fmi2Integer x = v;
            ok(fn.fmi2SetInteger(c, &r, 1, &x));
        }
        ok(fn.fmi2ExitInitializationMode(c));
        return c;
    }
    void set(fmi2Component c, const std::string& n, double v) {
        const fmi2ValueReference r = d.vr.at(n);
        ok(fn.fmi2SetReal(c, &r, 1, &v));
    }
    double get(fmi2Component c, const std::string& n) {
        const fmi2ValueReference r = d.vr.at(n);
        double v = 0;
        ok(fn.fmi2GetReal(c, &r, 1, &v));
        return v;
    }
    static void ok(fmi2Status s) {
        if (s > fmi2Warning) {
            std::fprintf(stderr, "FMI call failed (%d)\n", static_cast<int>(s));
            std::exit(3);
        }
    }
};

struct Trace {
    const char* name;
    double psi0[2], i0[2];
    std::vector<double> u_d, u_q;
    double T_e_end = 0, i_d_end = 0, i_q_end = 0;
};

// The closed loop (the controller's and the plant's models coupled on the drive's coupling
// description, started at rest and then held at top speed); records the plant's voltages after
// 20 ms of settling: the voltage applied over each step, read back from the plant's inputs.
Trace record(const std::string& flux_map, const char* name, const std::function<double(int)>& torque, int n) {
    try {
        fmi::Context ctx;
        ctx.instance_name = "bench";
        ctx.resource_dir = ipmsm::source_path("fmu_src/resources");
        ctx.log_warning = [](const std::string& m) { std::fprintf(stderr, "model: %s\n", m.c_str()); };
        ControllerModel controller(ctx);
        PlantModel plant(ctx);
        // Both models on the same map (their default map when flux_map is empty).
        controller.motor.flux_map = plant.motor.flux_map = flux_map;
        const coupling::Coupling description = coupling::parse(coupling::kDriveCouplingText);
        std::vector<coupling::ModelUnit> units;
        for (const coupling::Unit& u : description.units) {
            if (u.model_identifier == PlantModel::model_identifier)
                units.push_back(coupling::model_unit(plant));
            else if (u.model_identifier == ControllerModel::model_identifier)
                units.push_back(coupling::model_unit(controller));
            else
                throw std::invalid_argument("the coupling description has a unit " + u.model_identifier);
        }
        coupling::CoupledModels loop(description, std::move(units), kH);
        const auto hold = [&](double T_ref, double w_m) {
            loop.hold("T_ref", T_ref);
            loop.hold("w_m", w_m);
            loop.hold("u_dc", 355.0);
            loop.hold("T_magnet", 293.15);
            loop.hold("T_winding", 293.15);
        };
        hold(0.0, 0.0);
        loop.initialise();
        const int settle = 200;
        hold(torque(0), kTopSpeed);
        for (int k = 0; k < settle; ++k) loop.step();
        Trace tr;
        tr.name = name;
        tr.psi0[0] = plant.psi_d, tr.psi0[1] = plant.psi_q;
        tr.i0[0] = plant.i_d, tr.i0[1] = plant.i_q;
        for (int k = 0; k < n; ++k) {
            hold(torque(k), kTopSpeed);
            loop.step();
            tr.u_d.push_back(plant.u_d);
            tr.u_q.push_back(plant.u_q);
        }
        tr.T_e_end = plant.T_e;
        tr.i_d_end = plant.i_d;
        tr.i_q_end = plant.i_q;
        return tr;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "recording the closed loop: %s\n", e.what());
        std::exit(3);
    }
}

struct Result {
    double us_per_step = 0;
    double steps = 0, rhs = 0;  // per communication step
    std::vector<double> i;      // i_d, i_q per step, for the error
};

Result replay(const Trace& tr, const InverseFluxMap& inv, const CvodeSettings& s, int rounds) {
    Result r;
    DqFluxOde ode;
    ode.inverse = &inv;
    ode.omega = kPolePairs * kTopSpeed;
    ode.R = kRs;
    const std::size_t n = tr.u_d.size();
    double best = 1e300;
    for (int round = 0; round < rounds; ++round) {
        CvodeIntegrator integ(s);
        integ.reset(0.0, tr.psi0[0], tr.psi0[1]);
        long steps = 0, rhs = 0;
        std::vector<double> cur;
        cur.reserve(2 * n);
        // The first step creates CVODE's workspace (once per instance): not timed.
        ode.u_d = tr.u_d[0];
        ode.u_q = tr.u_q[0];
        integ.advance(ode, kH);
        const auto t0 = std::chrono::steady_clock::now();
        for (std::size_t k = 1; k < n; ++k) {
            ode.u_d = tr.u_d[k];
            ode.u_q = tr.u_q[k];
            integ.advance(ode, kH);
            steps += integ.stats().steps;
            rhs += integ.stats().rhs_evals;
        }
        const auto t1 = std::chrono::steady_clock::now();
        best = std::min(best, std::chrono::duration<double, std::micro>(t1 - t0).count() / (n - 1));
        if (round == 0) {
            // Currents along the trajectory (outside the timed loop: a second pass).
            CvodeIntegrator again(s);
            again.reset(0.0, tr.psi0[0], tr.psi0[1]);
            for (std::size_t k = 0; k < n; ++k) {
                ode.u_d = tr.u_d[k];
                ode.u_q = tr.u_q[k];
                again.advance(ode, kH);
                const InverseFluxPoint c = inv.eval(again.state().psi[0], again.state().psi[1]);
                cur.push_back(c.i_d);
                cur.push_back(c.i_q);
            }
            r.i = std::move(cur);
            r.steps = static_cast<double>(steps) / (n - 1);
            r.rhs = static_cast<double>(rhs) / (n - 1);
        }
    }
    r.us_per_step = best;
    return r;
}

double max_error(const std::vector<double>& a, const std::vector<double>& b) {
    double e = 0;
    for (std::size_t k = 0; k < a.size() && k < b.size(); ++k) e = std::max(e, std::abs(a[k] - b[k]));
    return e;
}

// fmi2SetReal (u_d, u_q, w_m) + fmi2DoStep through the FMU, microseconds per step (best round).
double fmu_replay(Fmu& plant_fmu, const Trace& tr, std::map<std::string, double> reals,
                  const std::map<std::string, int>& ints, int rounds, double* do_step_only) {
    double best = 1e300, best_step = 1e300;
    const std::size_t n = tr.u_d.size();
    const fmi2ValueReference in_vr[3] = {plant_fmu.d.vr.at("u_d"), plant_fmu.d.vr.at("u_q"), plant_fmu.d.vr.at("w_m")};
    for (int round = 0; round < rounds; ++round) {
        // Starts at the recorded currents (so at the recorded fluxes, to the inverse map's accuracy).
        reals["i_d_start"] = tr.i0[0];
        reals["i_q_start"] = tr.i0[1];
        fmi2Component c = plant_fmu.make("bench", reals, ints);
        double step_us = 0;
        double in[3] = {tr.u_d[0], tr.u_q[0], kTopSpeed};
        Fmu::ok(plant_fmu.fn.fmi2SetReal(c, in_vr, 3, in));
        Fmu::ok(plant_fmu.fn.fmi2DoStep(c, 0.0, kH, fmi2True));  // creates the workspace: not timed
        const auto t0 = std::chrono::steady_clock::now();
        for (std::size_t k = 1; k < n; ++k) {
            in[0] = tr.u_d[k];
            in[1] = tr.u_q[k];
            Fmu::ok(plant_fmu.fn.fmi2SetReal(c, in_vr, 3, in));
            const auto s0 = std::chrono::steady_clock::now();
            Fmu::ok(plant_fmu.fn.fmi2DoStep(c, k * kH, kH, fmi2True));
            step_us += std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - s0).count();
        }
        const auto t1 = std::chrono::steady_clock::now();
        best = std::min(best, std::chrono::duration<double, std::micro>(t1 - t0).count() / (n - 1));
        best_step = std::min(best_step, step_us / (n - 1));
        plant_fmu.fn.fmi2FreeInstance(c);
    }
    *do_step_only = best_step;
    return best;
}

}  // namespace

int main(int argc, char** argv) {
    const int rounds = argc > 1 ? std::max(1, std::atoi(argv[1])) : 7;
    const fs::path fmu_dir = fs::read_symlink("/proc/self/exe").parent_path().parent_path() / "fmu";
    Fmu plant(fmu_dir / "IpmsmPlant", "IpmsmPlant");

    const std::string map_path =
        argc > 2 ? std::string(argv[2]) : ipmsm::source_path("fmu_src/resources/ev_ipmsm_default.csv");
    const std::string custom_map = argc > 2 ? map_path : std::string();
    if (argc > 2) plant.flux_map = map_path;
    std::printf("flux map %s\n", map_path.c_str());
    const FluxMap map(read_flux_map(map_path));
    const InverseFluxMap inv(map);

    const int n = 1000;
    // Torque commands after 20 ms at the first value: 60 N.m held (the current regulator corrects
    // a little every step), 80 N.m held (about the maximum: the voltage is at its limit), a ramp
    // 20 -> 80 N.m over the 100 ms, and steps 80 / 40 N.m every 10 ms (current transients).
    std::vector<Trace> traces = {record(
                                     custom_map, "60Nm", [](int) { return 60.0; }, n),
                                 record(
                                     custom_map, "80Nm", [](int) { return 80.0; }, n),
                                 record(
                                     custom_map, "ramp", [n](int k) { return 20.0 + 60.0 * k / n; }, n),
                                 record(
                                     custom_map, "steps", [](int k) { return (k / 100) % 2 == 1 ? 40.0 : 80.0; }, n)};
    for (const Trace& tr : traces)
        std::printf("trace %-6s: 12000 r/min, %d steps of 100 us; at the end T_e = %.2f N.m, i = (%.1f, %.1f) A\n",
                    tr.name, n, tr.T_e_end, tr.i_d_end, tr.i_q_end);

    struct Variant {
        std::string name;
        CvodeSettings s;
    };
    // The FMU's choice (PlantModel::settings()) and one change at a time.
    CvodeSettings chosen;
    chosen.method = CvodeMethod::adams;
    chosen.nonlinear = CvodeNonlinear::fixed_point;
    chosen.rtol = 1e-6;
    chosen.atol = 1e-8;
    chosen.init_step = CvodeInitStep::curvature;
    chosen.nonlin_conv_coef = 0.3;
    auto with = [&](const std::function<void(CvodeSettings&)>& change) {
        CvodeSettings s = chosen;
        change(s);
        return s;
    };
    auto tol_name = [](const char* what, double r, double a) {
        char b[120];
        std::snprintf(b, sizeof b, "%s rtol %.0e atol %.0e", what, r, a);
        return std::string(b);
    };
    std::vector<Variant> variants = {
        {"FMU choice: linearised, Adams, fixed point, reinit, h0 curvature, nlscoef 0.3, 1e-6/1e-8", chosen},
        {"  direct (CVODE on dpsi/dt itself; the FMU's choice before, rtol atol 1e-6)", with([](auto& s) {
             s.linearised = false;
             s.atol = 1e-6;
         })},
        {"  linearised, rtol atol 1e-6 (the FMU's tolerances before)", with([](auto& s) { s.atol = 1e-6; })},
        {"  h0: last step of the previous call", with([](auto& s) { s.init_step = CvodeInitStep::previous_last; })},
        {"  nlscoef 0.1 (CVODE's default)", with([](auto& s) { s.nonlin_conv_coef = 0; })},
        {"  nlscoef 0.5", with([](auto& s) { s.nonlin_conv_coef = 0.5; })},
        {"  max order 2", with([](auto& s) { s.max_order = 2; })},
        {"  Newton, analytic Jacobian", with([](auto& s) { s.nonlinear = CvodeNonlinear::newton_analytic; })},
    };
    for (auto [r, a] : {std::pair{1e-4, 1e-4}, {1e-5, 1e-5}, {3e-6, 3e-6}, {1e-6, 1e-7}, {1e-7, 1e-7}, {1e-8, 1e-8}})
        variants.push_back({tol_name(" ", r, a), with([r = r, a = a](auto& s) {
                                s.rtol = r;
                                s.atol = a;
                            })});
    variants.push_back({"BDF, Newton, analytic J, reinit, h0 curvature (FMU cvode_method 2)", with([](auto& s) {
                            s.method = CvodeMethod::bdf;
                            s.nonlinear = CvodeNonlinear::newton_analytic;
                        })});
    variants.push_back({"  difference-quotient Jacobian", with([](auto& s) {
                            s.method = CvodeMethod::bdf;
                            s.nonlinear = CvodeNonlinear::newton_dq;
                        })});

    for (const Trace& tr : traces) {
        // Reference: Adams on dpsi/dt itself at rtol 1e-12, atol 1e-14 Wb.
        CvodeSettings ref;
        ref.linearised = false;
        ref.rtol = 1e-12;
        ref.atol = 1e-14;
        ref.max_steps = 1000000;
        const Result reference = replay(tr, inv, ref, 1);
        std::printf("\n== trace %s: replay through CvodeIntegrator (%d rounds, best)\n", tr.name, rounds);
        std::printf("%-72s %9s %7s %7s %12s\n", "setting", "us/step", "steps", "RHS", "max |di| A");
        for (const Variant& v : variants) {
            const Result r = replay(tr, inv, v.s, rounds);
            std::printf("%-72s %9.3f %7.2f %7.2f %12.3e\n", v.name.c_str(), r.us_per_step, r.steps, r.rhs,
                        max_error(r.i, reference.i));
        }
        std::printf("-- the whole FMI call (fmi2SetReal of u_d, u_q, w_m + fmi2DoStep), FMU %s\n",
                    (fmu_dir / "IpmsmPlant.fmu").c_str());
        double step_only = 0;
        double all = fmu_replay(plant, tr, {}, {}, rounds, &step_only);
        std::printf("%-72s %9.3f  (fmi2DoStep alone %.3f us)\n",
                    "FMU defaults (linearised, Adams, rtol 1e-6, atol 1e-8)", all, step_only);
        all = fmu_replay(plant, tr, {{"rtol", 3e-6}, {"atol", 3e-6}}, {}, rounds, &step_only);
        std::printf("%-72s %9.3f  (fmi2DoStep alone %.3f us)\n", "FMU rtol 3e-6, atol 3e-6", all, step_only);
        all = fmu_replay(plant, tr, {}, {{"cvode_method", 2}}, rounds, &step_only);
        std::printf("%-72s %9.3f  (fmi2DoStep alone %.3f us)\n", "FMU cvode_method 2 (BDF, Newton, analytic J)", all,
                    step_only);
    }
    return 0;
}
