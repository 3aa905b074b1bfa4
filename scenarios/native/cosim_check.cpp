// A driver of libipmsm_cosim's C API without Python: for valgrind, and for timing without ctypes.
//   cosim_check <unzipped controller dir> <unzipped plant dir> [simulated seconds = 0.05]
// Runs: two masters (the second only briefly, interleaved), a drive-like profile in 10 ms chunks
// with probes and a trace, a refused input (u_dc = 0: an error, the master stays usable), a
// failing step (a NaN after a bad parameter is impossible to set, so: a step with the plant's
// cvode_max_steps = 1 at full voltage), then frees everything. Exit status 0 if all checks passed.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "cosim.h"
#include "fmu_description.hpp"

namespace {

int failures = 0;
#define CHECK(cond)                                                                  \
    do {                                                                             \
        if (!(cond)) {                                                               \
            std::fprintf(stderr, "CHECK failed at line %d: %s\n", __LINE__, #cond); \
            ++failures;                                                              \
        }                                                                            \
    } while (0)

using cosim_tools::Description;
using cosim_tools::read_description;

int logged = 0;
void log_fn(void*, int unit, const char* instance, int status, const char* category, const char* message) {
    ++logged;
    if (status >= 1) std::printf("  [log unit %d %s status %d %s] %s\n", unit, instance, status, category, message);
}

struct Setup {
    ipmsm_cosim* m = nullptr;
    std::vector<std::string> names;
};

Setup make(const std::string& cdir, const std::string& pdir, const Description& cd, const Description& pd,
           const char* suffix, double w_m, int plant_max_steps = 0) {
    Setup s;
    s.m = ipmsm_cosim_new(1e-4, log_fn, nullptr);
    ipmsm_cosim* m = s.m;
    auto ok = [&](int rc) {
        if (rc != 0) {
            std::fprintf(stderr, "unexpected failure: %s\n", ipmsm_cosim_error(m));
            std::exit(1);
        }
    };
    ok(ipmsm_cosim_instantiate(m, 0, cdir.c_str(), "IpmsmController", cd.guid.c_str(),
                               (std::string("controller") + suffix).c_str(), 0));
    ok(ipmsm_cosim_instantiate(m, 1, pdir.c_str(), "IpmsmPlant", pd.guid.c_str(), (std::string("plant") + suffix).c_str(), 0));
    ok(cosim_tools::start_coupled(m, cd, pd, {0.0, w_m, 355.0, 353.15, 373.15}, [&](ipmsm_cosim* mm) {
        int rc = 0;
        if (plant_max_steps > 0) {
            const unsigned vr = pd.vr.at("cvode_max_steps");
            rc = ipmsm_cosim_set_integer(mm, 1, 1, &vr, &plant_max_steps);
        }
        const char* empty = "";
        const unsigned map_vr = pd.vr.at("flux_map");
        return rc != 0 ? rc : ipmsm_cosim_set_string(mm, 1, 1, &map_vr, &empty);
    }));
    std::vector<int> unit, kind;
    std::vector<unsigned> vr;
    for (const char* n : {"T_shaft", "T_e", "P_elec", "P_mech", "P_cu", "P_fe", "i_d", "i_q"}) {
        unit.push_back(1), kind.push_back(IPMSM_COSIM_REAL), vr.push_back(pd.vr.at(n));
        s.names.push_back(n);
    }
    unit.push_back(1), kind.push_back(IPMSM_COSIM_CURRENT_ABS), vr.push_back(0), s.names.push_back("|i|");
    unit.push_back(1), kind.push_back(IPMSM_COSIM_CURRENT_SQ), vr.push_back(0), s.names.push_back("|i|^2");
    for (const char* n : {"T_cmd", "T_max"}) {
        unit.push_back(0), kind.push_back(IPMSM_COSIM_REAL), vr.push_back(cd.vr.at(n));
        s.names.push_back(n);
    }
    for (const char* n : {"region", "iterations"}) {
        unit.push_back(0), kind.push_back(IPMSM_COSIM_INTEGER), vr.push_back(cd.vr.at(n));
        s.names.push_back(n);
    }
    ok(ipmsm_cosim_probes(m, unit.size(), unit.data(), kind.data(), vr.data()));
    return s;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 3) {
        std::fprintf(stderr, "usage: %s <unzipped controller dir> <unzipped plant dir> [seconds]\n", argv[0]);
        return 2;
    }
    const std::string cdir = argv[1], pdir = argv[2];
    const double seconds = argc > 3 ? std::atof(argv[3]) : 0.05;
    const Description cd = read_description(cdir), pd = read_description(pdir);

    // Two masters, interleaved: the second must not disturb the first.
    Setup a = make(cdir, pdir, cd, pd, "_a", 100.0);
    Setup b = make(cdir, pdir, cd, pd, "_b", 300.0);
    const size_t np = a.names.size();
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
        const double slow[5] = {T_ref, w_m, 355.0, 353.15, 373.15};
        const long long rows = ipmsm_cosim_advance(a.m, chunk, slow, mean.data(), end.data(), trace.data(),
                                                   static_cast<long long>(trace.size() / (np + 1)), 10);
        if (rows < 0) {
            std::fprintf(stderr, "advance failed: %s\n", ipmsm_cosim_error(a.m));
            return 1;
        }
        CHECK(rows == chunk / 10);
        energy += mean[2] * 0.01;
        if (c < 3) {  // interleave the second master
            const double slow_b[5] = {50.0, 300.0, 355.0, 353.15, 373.15};
            CHECK(ipmsm_cosim_advance(b.m, 7, slow_b, mean.data(), end.data(), nullptr, 0, 0) == 0);
        }
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const long long steps = chunks * chunk;
    std::printf("%lld coupled steps (%.3f s simulated) in %.3f s: %.3f us/step, real-time factor %.2f; E_elec %.1f J\n",
                steps, steps * 1e-4, wall, wall / steps * 1e6, steps * 1e-4 / wall, energy);
    CHECK(ipmsm_cosim_step_index(a.m) == steps);
    CHECK(ipmsm_cosim_time(a.m) == steps * 1e-4);
    CHECK(std::isfinite(energy));

    // A refused slow input: an error that names the FMU; nothing changes, the master goes on.
    const double bad[5] = {10.0, 100.0, 0.0, 353.15, 373.15};
    CHECK(ipmsm_cosim_advance(a.m, 10, bad, mean.data(), end.data(), nullptr, 0, 0) == -1);
    std::printf("refused: %s\n", ipmsm_cosim_error(a.m));
    CHECK(std::strstr(ipmsm_cosim_error(a.m), "IpmsmController") != nullptr);
    CHECK(ipmsm_cosim_step_index(a.m) == steps);
    const double good[5] = {10.0, 100.0, 355.0, 353.15, 373.15};
    CHECK(ipmsm_cosim_advance(a.m, 10, good, mean.data(), end.data(), nullptr, 0, 0) == 0);
    ipmsm_cosim_free(a.m);
    ipmsm_cosim_free(b.m);

    // A failing step (CVODE needs more than one internal step): the master stops there.
    Setup c = make(cdir, pdir, cd, pd, "_c", 1000.0, 1);
    const double strong[5] = {200.0, 1000.0, 355.0, 353.15, 373.15};
    long long r = 0;
    for (int i = 0; i < 50 && r >= 0; ++i) r = ipmsm_cosim_advance(c.m, 10, strong, mean.data(), end.data(), nullptr, 0, 0);
    CHECK(r == -1);
    std::printf("failed step: %s\n", ipmsm_cosim_error(c.m));
    CHECK(std::strstr(ipmsm_cosim_error(c.m), "IpmsmPlant") != nullptr);
    CHECK(std::strstr(ipmsm_cosim_error(c.m), "fmi2DoStep") != nullptr);
    CHECK(ipmsm_cosim_advance(c.m, 1, strong, mean.data(), end.data(), nullptr, 0, 0) == -1);
    ipmsm_cosim_free(c.m);

    // Failures before coupling: a missing library, a wrong GUID.
    ipmsm_cosim* d = ipmsm_cosim_new(1e-4, nullptr, nullptr);
    CHECK(ipmsm_cosim_instantiate(d, 0, "/nonexistent", "IpmsmController", cd.guid.c_str(), "x", 0) == -1);
    CHECK(ipmsm_cosim_instantiate(d, 1, pdir.c_str(), "IpmsmPlant", "{wrong}", "x", 0) == -1);
    std::printf("wrong GUID: %s\n", ipmsm_cosim_error(d));
    ipmsm_cosim_free(d);
    CHECK(ipmsm_cosim_new(0.0, nullptr, nullptr) == nullptr);

    std::printf("%s (%d log messages)\n", failures == 0 ? "all checks passed" : "FAILED", logged);
    return failures == 0 ? 0 : 1;
}
