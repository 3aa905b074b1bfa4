// A driver of libipmsm_cosim's C API without Python: for valgrind, and for timing without ctypes.
//   cosim_check <unzipped controller dir> <unzipped plant dir> [simulated seconds = 0.05]
// Runs: two masters (the second only briefly, interleaved), a drive-like profile in 10 ms chunks
// with probes and a trace, a refused input (u_dc = 0: an error, the master stays usable), a
// failing step (a NaN after a bad parameter is impossible to set, so: a step with the plant's
// cvode_max_steps = 1 at full voltage), failures before coupling (wrong FMU for a role, unusable
// coupling descriptions), then frees everything. Exit status 0 if all checks passed.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "check.hpp"
#include "cosim.h"
#include "fmu_description.hpp"

namespace {

using cosim_tools::Description;
using cosim_tools::read_description;

int logged = 0;
void log_fn(void*, const char* role, const char* instance, int status, const char* category, const char* message) {
    ++logged;
    if (status >= 1) std::printf("  [log %s %s status %d %s] %s\n", role, instance, status, category, message);
}

// What every master here reports (the names resolve through the model descriptions).
const std::vector<const char*>& kProbes = cosim_tools::kDriveOutputs;
const size_t kP_elec = cosim_tools::index_of(kProbes, "plant.P_elec");

ipmsm_cosim* make(const std::string& cdir, const std::string& pdir, const Description& pd, const char* suffix,
                  double w_m, int plant_max_steps = 0) {
    cosim_tools::Units units{cdir, pdir, std::string("controller") + suffix, std::string("plant") + suffix};
    std::string why;
    ipmsm_cosim* m = cosim_tools::start_drive(
        units, 1e-4, {0.0, w_m, 355.0, 353.15, 373.15}, kProbes, why,
        [&](ipmsm_cosim* mm) {
            int rc = 0;
            if (plant_max_steps > 0) {
                const unsigned vr = pd.vr.at("cvode_max_steps");
                rc = ipmsm_cosim_set_integer(mm, "plant", 1, &vr, &plant_max_steps);
            }
            const char* empty = "";
            const unsigned map_vr = pd.vr.at("flux_map");
            return rc != 0 ? rc : ipmsm_cosim_set_string(mm, "plant", 1, &map_vr, &empty);
        },
        log_fn);
    if (m == nullptr) {
        std::fprintf(stderr, "unexpected failure: %s\n", why.c_str());
        std::exit(1);
    }
    return m;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 3) {
        std::fprintf(stderr, "usage: %s <unzipped controller dir> <unzipped plant dir> [seconds]\n", argv[0]);
        return 2;
    }
    const std::string cdir = argv[1], pdir = argv[2];
    const double seconds = argc > 3 ? std::atof(argv[3]) : 0.05;
    const Description pd = read_description(pdir);

    // Two masters, interleaved: the second must not disturb the first.
    ipmsm_cosim* a = make(cdir, pdir, pd, "_a", 100.0);
    ipmsm_cosim* b = make(cdir, pdir, pd, "_b", 300.0);
    const size_t np = kProbes.size();
    std::vector<double> mean(np), end(np);
    const long long chunk = 100;  // 10 ms
    const long long chunks = static_cast<long long>(std::llround(seconds / 0.01));
    std::vector<double> trace(static_cast<size_t>(chunk / 10) * (np + 1));
    double energy = 0.0;
    const auto t0 = std::chrono::steady_clock::now();
    const double w_top = 12000.0 * 2.0 * M_PI / 60.0;
    for (long long c = 0; c < chunks; ++c) {
        const double t = c * 0.01, x = chunks > 1 ? static_cast<double>(c) / (chunks - 1) : 0.0;
        const double w_m = 100.0 + (w_top - 100.0) * (x < 0.5 ? 2 * x : 2 - 2 * x);
        const double T_ref = 150.0 * std::sin(2 * M_PI * t / 0.4) + ((c / 7) % 2 ? 80.0 : -40.0);
        const ipmsm_cosim_inputs in{T_ref, w_m, 355.0, 353.15, 373.15};
        const long long rows = ipmsm_cosim_advance(a, chunk, &in, mean.data(), end.data(), trace.data(),
                                                   static_cast<long long>(trace.size() / (np + 1)), 10);
        if (rows < 0) {
            std::fprintf(stderr, "advance failed: %s\n", ipmsm_cosim_error(a));
            return 1;
        }
        CHECK(rows == chunk / 10);
        energy += mean[kP_elec] * 0.01;
        if (c < 3) {  // interleave the second master
            const ipmsm_cosim_inputs in_b{50.0, 300.0, 355.0, 353.15, 373.15};
            CHECK(ipmsm_cosim_advance(b, 7, &in_b, mean.data(), end.data(), nullptr, 0, 0) == 0);
        }
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const long long steps = chunks * chunk;
    std::printf("%lld coupled steps (%.3f s simulated) in %.3f s: %.3f us/step, real-time factor %.2f; E_elec %.1f J\n",
                steps, steps * 1e-4, wall, wall / steps * 1e6, steps * 1e-4 / wall, energy);
    CHECK(ipmsm_cosim_step_index(a) == steps);
    CHECK(ipmsm_cosim_time(a) == steps * 1e-4);
    CHECK(std::isfinite(energy));

    // A refused external input: an error that names the FMU; k unchanged, the master goes on.
    const ipmsm_cosim_inputs bad{10.0, 100.0, 0.0, 353.15, 373.15};
    CHECK(ipmsm_cosim_advance(a, 10, &bad, mean.data(), end.data(), nullptr, 0, 0) == -1);
    std::printf("refused: %s\n", ipmsm_cosim_error(a));
    CHECK(std::strstr(ipmsm_cosim_error(a), "IpmsmController") != nullptr);
    CHECK(ipmsm_cosim_step_index(a) == steps);
    const ipmsm_cosim_inputs good{10.0, 100.0, 355.0, 353.15, 373.15};
    CHECK(ipmsm_cosim_advance(a, 10, &good, mean.data(), end.data(), nullptr, 0, 0) == 0);
    ipmsm_cosim_free(a);
    ipmsm_cosim_free(b);

    // A failing step (CVODE needs more than one internal step): the master stops there.
    ipmsm_cosim* c = make(cdir, pdir, pd, "_c", 1000.0, 1);
    const ipmsm_cosim_inputs strong{200.0, 1000.0, 355.0, 353.15, 373.15};
    long long r = 0;
    for (int i = 0; i < 50 && r >= 0; ++i)
        r = ipmsm_cosim_advance(c, 10, &strong, mean.data(), end.data(), nullptr, 0, 0);
    CHECK(r == -1);
    std::printf("failed step: %s\n", ipmsm_cosim_error(c));
    CHECK(std::strstr(ipmsm_cosim_error(c), "IpmsmPlant") != nullptr);
    CHECK(std::strstr(ipmsm_cosim_error(c), "fmi2DoStep") != nullptr);
    CHECK(ipmsm_cosim_advance(c, 1, &strong, mean.data(), end.data(), nullptr, 0, 0) == -1);
    ipmsm_cosim_free(c);

    // Failures before coupling: a missing folder, the wrong FMU for a role, an unknown role.
    ipmsm_cosim* d = ipmsm_cosim_new(ipmsm::coupling::kDriveCouplingText, 1e-4, nullptr, nullptr);
    CHECK(ipmsm_cosim_instantiate(d, "controller", "/nonexistent", "x", 0) == -1);
    CHECK(ipmsm_cosim_instantiate(d, "controller", pdir.c_str(), "x", 0) == -1);
    std::printf("wrong FMU: %s\n", ipmsm_cosim_error(d));
    CHECK(std::strstr(ipmsm_cosim_error(d), "must be IpmsmController") != nullptr);
    CHECK(ipmsm_cosim_instantiate(d, "motor", cdir.c_str(), "x", 0) == -1);
    CHECK(ipmsm_cosim_enter_initialization(d) == -1);
    ipmsm_cosim_free(d);
    CHECK(ipmsm_cosim_new(ipmsm::coupling::kDriveCouplingText, 0.0, nullptr, nullptr) == nullptr);

    // Descriptions that cannot be used: a syntax error (named by its line), a variable the FMU
    // lacks (named when the names are resolved), an external input ipmsm_cosim_inputs lacks.
    ipmsm_cosim* e = ipmsm_cosim_new("unit plant IpmsmPlant\nstep 1e-4\nplant.i_d => x\n", 1e-4, nullptr, nullptr);
    CHECK(ipmsm_cosim_instantiate(e, "plant", pdir.c_str(), "x", 0) == -1);
    std::printf("bad description: %s\n", ipmsm_cosim_error(e));
    CHECK(std::strstr(ipmsm_cosim_error(e), "line 3") != nullptr);
    ipmsm_cosim_free(e);
    for (const char* text : {"unit plant IpmsmPlant\nunit controller IpmsmController\nstep 1e-4\n"
                             "controller.u_d_ref -> plant.u_x\n",
                             "unit plant IpmsmPlant\nstep 1e-4\nspeed -> plant.w_m\n"}) {
        ipmsm_cosim* f = ipmsm_cosim_new(text, 1e-4, nullptr, nullptr);
        int rc = ipmsm_cosim_instantiate(f, "plant", pdir.c_str(), "x", 0);
        if (std::strstr(text, "controller") != nullptr && rc == 0)
            rc = ipmsm_cosim_instantiate(f, "controller", cdir.c_str(), "y", 0);
        if (rc == 0) rc = ipmsm_cosim_enter_initialization(f);
        CHECK(rc == 0);
        const ipmsm_cosim_inputs start{0.0, 0.0, 355.0, 293.15, 293.15};
        CHECK(ipmsm_cosim_initialize(f, &start) == -1);
        std::printf("unresolved: %s\n", ipmsm_cosim_error(f));
        CHECK(std::strstr(ipmsm_cosim_error(f), "u_x") != nullptr ||
              std::strstr(ipmsm_cosim_error(f), "speed") != nullptr);
        ipmsm_cosim_free(f);
    }

    std::printf("%s (%d log messages)\n", check::failures == 0 ? "all checks passed" : "FAILED", logged);
    return check::failures == 0 ? 0 : 1;
}
