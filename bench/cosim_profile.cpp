// Where the time of a coupled step goes: the drive-like profile of bench/bench_cosim.py run
//   A  through the FMUs with libipmsm_cosim (the native master, 10 ms chunks, the 15 outputs of
//      scenarios/cosim/master.py's Sample)
//   A0 the same with 2 probes (T_e, i_d: the bit-compare)
//   B  the two models called directly, no FMI (ControllerModel, PlantModel linked in: the same
//      sources as the FMUs), coupled by fmu_src/coupling/coupled_models.hpp on the same coupling
//      description: the models' own compute; the plant's and the controller's do_step timed
//      separately (rdtsc)
//   C  B plus what the glue's undoable() does per step besides the call: copy-assign each model
//      to a backup, check the computed Reals are finite, and build the "the step from t = ..."
//      text it passes (fmi2_functions.hpp do_step)
// A and B must agree bit for bit (checked). A - C is then the rest of the FMI glue (set/get
// validation, state checks, the call boundary) plus the master's loop.
//   cosim_profile <unzipped controller dir> <unzipped plant dir> [seconds = 10] [repeats = 3] [drive|stress]
#include <time.h>
#include <x86intrin.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "controller/controller_model.hpp"
#include "coupling/coupled_models.hpp"
#include "coupling/drive_coupling_text.hpp"
#include "fmi2_support.hpp"
#include "fmu_description.hpp"
#include "plant_model.hpp"

namespace {

constexpr double kH = 1e-4;
constexpr long long kChunk = 100;

// As bench/bench_cosim.py: profile(t, duration).
double torque_pattern(double t) {
    const double x = std::fmod(t, 10.0);
    if (x < 2.0) return 150.0;
    if (x < 4.0) return 150.0 - 50.0 * (x - 2.0);
    if (x < 6.0) return -80.0;
    if (x < 8.0) return -80.0 + 150.0 * (x - 6.0);
    return 0.0;
}

bool g_stress = false;  // the "stress" profile: a new pseudo-random torque every 10 ms

double stress_torque(double t) {
    const long long j = std::llround(t / (kChunk * kH));
    const double x = static_cast<double>((j * 2654435761LL + 12345) % 4294967296LL) / 4294967296.0;
    return -250.0 + 500.0 * x;
}

ipmsm_cosim_inputs profile(double t, double duration) {
    const double x = t / duration, top = 12000.0 * 2.0 * M_PI / 60.0;
    double w_m = top * std::min({1.0, x / 0.4, (1.0 - x) / 0.4});
    w_m = std::max(w_m, 0.0);
    const double T_ref = g_stress ? stress_torque(t) : torque_pattern(t);
    return {T_ref, w_m, 355.0 - 2.5e-4 * T_ref * w_m, 273.15 + 60.0 + 30.0 * x, 273.15 + 70.0 + 40.0 * x};
}

double cpu_now() {
    timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

struct Result {
    double cpu = 0, wall = 0;                                            // s
    double plant = 0, controller = 0, copies = 0, text = 0, checks = 0;  // s (B, C: rdtsc-timed parts)
    double check = 0;  // sum of T_e over all steps, and the last i_d (bit-compare)
    double last_i_d = 0;
};

Result run_fmus(const cosim_tools::Units& units, double seconds, bool probes) {
    // all the drive's outputs, or T_e and i_d only (the bit-compare)
    const std::vector<const char*> names =
        probes ? cosim_tools::kDriveOutputs : std::vector<const char*>{"plant.T_e", "plant.i_d"};
    const size_t T_e = cosim_tools::index_of(names, "plant.T_e"), i_d = cosim_tools::index_of(names, "plant.i_d");
    std::string why;
    ipmsm_cosim* m = cosim_tools::start_drive(units, kH, profile(0.0, seconds), names, why);
    if (m == nullptr) {
        std::fprintf(stderr, "%s\n", why.c_str());
        std::exit(1);
    }
    std::vector<double> mean(names.size()), end(names.size());
    const long long chunks = std::llround(seconds / (kChunk * kH));
    Result r;
    const double c0 = cpu_now();
    const auto w0 = std::chrono::steady_clock::now();
    for (long long c = 0; c < chunks; ++c) {
        const ipmsm_cosim_inputs in = profile(c * kChunk * kH, seconds);
        if (ipmsm_cosim_advance(m, kChunk, &in, mean.data(), end.data(), nullptr, 0, 0) < 0) {
            std::fprintf(stderr, "%s\n", ipmsm_cosim_error(m));
            std::exit(1);
        }
        r.check += mean[T_e];  // the chunk's mean
    }
    r.cpu = cpu_now() - c0;
    r.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
    r.last_i_d = end[i_d];
    ipmsm_cosim_free(m);
    return r;
}

void hold(ipmsm::coupling::CoupledModels& drive, const ipmsm_cosim_inputs& in) {
    drive.hold("T_ref", in.T_ref);
    drive.hold("w_m", in.w_m);
    drive.hold("u_dc", in.u_dc);
    drive.hold("T_magnet", in.T_magnet);
    drive.hold("T_winding", in.T_winding);
}

// What the glue does per step besides the model's call (C), timed.
struct GlueExtras {
    bool on = false;
    unsigned long long copies = 0, text = 0, checks = 0;  // rdtsc ticks
    size_t text_bytes = 0;
    bool finite = true;
};

// unit.do_step = model.do_step timed into t_step (rdtsc); with glue.on, wrapped as the glue
// wraps it: a backup copy of the model and the step's text before, the finite check after.
template <class Model, class AllFinite>
void time_do_step(ipmsm::coupling::ModelUnit& unit, Model& model, Model& backup, unsigned long long& t_step,
                  GlueExtras& glue, AllFinite all_finite) {
    unit.do_step = [&model, &backup, &t_step, &glue, all_finite](double t, double h) {
        if (glue.on) {
            const unsigned long long a = __rdtsc();
            backup = model;
            const unsigned long long b = __rdtsc();
            const std::string what = "the step from t = " + fmi::number_text(t) + " by h = " + fmi::number_text(h);
            glue.text_bytes += what.size();
            glue.copies += b - a;
            glue.text += __rdtsc() - b;
        }
        const unsigned long long b = __rdtsc();
        model.do_step(t, h);
        const unsigned long long e = __rdtsc();
        t_step += e - b;
        if (glue.on) {
            glue.finite &= all_finite(model);
            glue.checks += __rdtsc() - e;
        }
    };
}

// The models coupled by coupled_models.hpp (the same description), each do_step timed.
Result run_models(const std::string& resources, double seconds, bool glue_extras, double ticks_per_s) {
    fmi::Context ctx;
    ctx.instance_name = "direct";
    ctx.resource_dir = resources;
    ipmsm::ControllerModel c(ctx), c_backup(ctx);
    ipmsm::PlantModel p(ctx), p_backup(ctx);
    unsigned long long t_plant = 0, t_ctrl = 0;
    GlueExtras glue;
    glue.on = glue_extras;
    ipmsm::coupling::ModelUnit plant = ipmsm::coupling::model_unit(p), controller = ipmsm::coupling::model_unit(c);
    time_do_step(plant, p, p_backup, t_plant, glue, [](const ipmsm::PlantModel& m) {
        return std::isfinite(m.i_d) && std::isfinite(m.i_q) && std::isfinite(m.psi_d) && std::isfinite(m.psi_q) &&
               std::isfinite(m.T_e) && std::isfinite(m.T_shaft) && std::isfinite(m.P_elec) && std::isfinite(m.P_mech) &&
               std::isfinite(m.P_cu) && std::isfinite(m.P_fe) && std::isfinite(m.psi_m_T) && std::isfinite(m.R_s_T);
    });
    time_do_step(controller, c, c_backup, t_ctrl, glue, [](const ipmsm::ControllerModel& m) {
        return std::isfinite(m.i_d_ref) && std::isfinite(m.i_q_ref) && std::isfinite(m.u_d_ref) &&
               std::isfinite(m.u_q_ref) && std::isfinite(m.T_cmd) && std::isfinite(m.T_max) && std::isfinite(m.T_est);
    });
    const ipmsm::coupling::Coupling coupling = ipmsm::coupling::parse(ipmsm::coupling::kDriveCouplingText);
    std::vector<ipmsm::coupling::ModelUnit> models(coupling.units.size());
    models[static_cast<size_t>(coupling.unit_index("plant"))] = plant;
    models[static_cast<size_t>(coupling.unit_index("controller"))] = controller;
    ipmsm::coupling::CoupledModels drive(coupling, models, kH);
    hold(drive, profile(0.0, seconds));
    drive.initialise();
    c_backup = c;
    p_backup = p;
    const long long chunks = std::llround(seconds / (kChunk * kH));
    Result r;
    const double c0 = cpu_now();
    const auto w0 = std::chrono::steady_clock::now();
    for (long long ch = 0; ch < chunks; ++ch) {
        hold(drive, profile(ch * kChunk * kH, seconds));
        double sum = 0.0;
        for (long long s = 0; s < kChunk; ++s) {
            drive.step();
            sum += p.T_e;
        }
        r.check += sum / kChunk;
    }
    r.cpu = cpu_now() - c0;
    r.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
    r.plant = t_plant / ticks_per_s;
    r.controller = t_ctrl / ticks_per_s;
    r.copies = glue.copies / ticks_per_s;
    r.text = glue.text / ticks_per_s;
    r.checks = glue.checks / ticks_per_s;
    r.last_i_d = p.i_d;
    if (!glue.finite || (glue_extras && glue.text_bytes == 0)) r.check = std::nan("");
    return r;
}

double calibrate_tsc() {
    const auto w0 = std::chrono::steady_clock::now();
    const unsigned long long t0 = __rdtsc();
    while (std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count() < 0.2) {}
    const unsigned long long t1 = __rdtsc();
    return (t1 - t0) / std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 3) {
        std::fprintf(stderr, "usage: %s <unzipped controller dir> <unzipped plant dir> [seconds] [repeats]\n", argv[0]);
        return 2;
    }
    const std::string cdir = argv[1], pdir = argv[2];
    const double seconds = argc > 3 ? std::atof(argv[3]) : 10.0;
    const int repeats = argc > 4 ? std::atoi(argv[4]) : 3;
    g_stress = argc > 5 && std::string(argv[5]) == "stress";
    const cosim_tools::Units units{cdir, pdir};
    const double tps = calibrate_tsc();
    const double steps = std::llround(seconds / (kChunk * kH)) * static_cast<double>(kChunk);
    auto best = [&](auto f) {
        Result b;
        b.cpu = 1e300;
        for (int i = 0; i < repeats; ++i) {
            Result r = f();
            if (r.cpu < b.cpu) b = r;
        }
        return b;
    };
    const Result a = best([&] { return run_fmus(units, seconds, true); });
    const Result a0 = best([&] { return run_fmus(units, seconds, false); });
    const Result b = best([&] { return run_models(pdir + "/resources", seconds, false, tps); });
    const Result c = best([&] { return run_models(pdir + "/resources", seconds, true, tps); });
    const double us = 1e6 / steps;
    std::printf(
        "%s profile of bench/bench_cosim.py, %.0f s simulated (%.0f coupled steps), best of %d, "
        "CPU time of this thread (us per coupled step):\n",
        g_stress ? "stress" : "drive", seconds, steps, repeats);
    std::printf("  A  FMUs through libipmsm_cosim, 15 probes      %6.3f   (wall %6.3f)\n", a.cpu * us, a.wall * us);
    std::printf("  A0 FMUs through libipmsm_cosim, 2 probes       %6.3f   (wall %6.3f)\n", a0.cpu * us, a0.wall * us);
    std::printf("  B  models called directly, no FMI              %6.3f   (wall %6.3f)\n", b.cpu * us, b.wall * us);
    std::printf("       plant do_step (CVODE + map)      %6.3f\n", b.plant * us);
    std::printf("       controller do_step               %6.3f\n", b.controller * us);
    std::printf("       loop, rdtsc                      %6.3f\n", b.cpu * us - (b.plant + b.controller) * us);
    std::printf("  C  B + the glue's per-step copies, finite checks and step text  %6.3f   (wall %6.3f)\n", c.cpu * us,
                c.wall * us);
    std::printf("       plant do_step                    %6.3f\n", c.plant * us);
    std::printf("       controller do_step               %6.3f\n", c.controller * us);
    std::printf("       model copies (backup = model)    %6.3f\n", c.copies * us);
    std::printf("       step text (number_text x2)       %6.3f\n", c.text * us);
    std::printf("       finite checks                    %6.3f\n", c.checks * us);
    std::printf("  A - C: the rest of the glue (set/get, validation, call boundary) + the master loop: %6.3f\n",
                (a.cpu - c.cpu) * us);
    std::printf("  A - A0: 13 more probes (one more fmi2GetReal per unit, one fmi2GetInteger): %6.3f\n",
                (a.cpu - a0.cpu) * us);
    // The FMU run and the direct run must be the same computation.
    const bool same = a.last_i_d == b.last_i_d && a.last_i_d == c.last_i_d && a.check == b.check && b.check == c.check;
    std::printf(
        "  A, B, C the same computation: %s (last i_d %.17g / %.17g / %.17g; sum of chunk means of T_e "
        "%.17g / %.17g / %.17g)\n",
        same ? "yes" : "NO", a.last_i_d, b.last_i_d, c.last_i_d, a.check, b.check, c.check);
    std::printf("  WLTC 1800 s at A: %.1f s CPU\n", a.cpu / steps * 18e6);
    return same ? 0 : 1;
}
