// A small FMI 2.0 master for the IpmsmPlant FMU's binary, meant to run under valgrind
// (tests/python/test_plant_valgrind.py): no Python, so every leak or invalid access reported is
// the FMU's. It dlopens <fmu_dir>/binaries/linux64/IpmsmPlant.so of an unzipped FMU and runs
//   1. instantiate -> initialise -> steps -> reset -> initialise -> steps -> terminate -> free
//   2. instantiate -> initialise -> steps -> free (without terminate)
//   3. FMU states: get, step, set back, step again (bit-identical), serialise, deserialise, and
//      free the instance with states still alive
//   4. errors: a missing flux map (fmi2Error, then free), a NaN input (refused), a CVODE failure
//      (cvode_max_steps = 1: fmi2Error with CVODE's message, then the instance is used again)
//   5. two instances interleaved give bit-identical outputs
// Usage: plant_fmu_harness <unzipped fmu dir> [steps]. Exit status 0 if every check passed.
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "check.hpp"
#include "fmi2Functions.h"
#include "fmu_binary.hpp"

namespace {

std::string last_log;
void logger(fmi2ComponentEnvironment, fmi2String, fmi2Status status, fmi2String category, fmi2String message, ...) {
    char buf[4096];
    va_list ap;
    va_start(ap, message);
    std::vsnprintf(buf, sizeof buf, message, ap);
    va_end(ap);
    last_log = buf;
    if (status >= fmi2Warning) std::fprintf(stdout, "  [log %s] %s\n", category, buf);
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s <unzipped IpmsmPlant fmu dir> [steps]\n", argv[0]);
        return 2;
    }
    const std::string dir = argv[1];
    const int steps = argc > 2 ? std::atoi(argv[2]) : 200;
    const fmu_binary::Description d = fmu_binary::read_description(dir);
    const std::string& guid = d.guid;
    const auto& vr = d.vr;
    fmu_binary::Functions api;
    api.open_or_exit(fmu_binary::library_path(dir, "IpmsmPlant"));

    const std::string resources = "file://" + dir + "/resources";
    fmi2CallbackFunctions cb{logger, nullptr, nullptr, nullptr, nullptr};
    const fmi2Real h = 1e-4;
    const std::vector<std::string> outs = {"i_d",     "i_q",    "psi_d",  "psi_q", "T_e",
                                           "T_shaft", "P_elec", "P_mech", "P_cu",  "P_fe"};
    std::vector<fmi2ValueReference> out_vr;
    for (const auto& n : outs) out_vr.push_back(vr.at(n));

    auto make = [&](const char* name) {
        fmi2Component c =
            api.fmi2Instantiate(name, fmi2CoSimulation, guid.c_str(), resources.c_str(), &cb, fmi2False, fmi2True);
        CHECK(c != nullptr);
        return c;
    };
    auto init = [&](fmi2Component c) {
        CHECK(api.fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK);
        CHECK(api.fmi2EnterInitializationMode(c) == fmi2OK);
        CHECK(api.fmi2ExitInitializationMode(c) == fmi2OK);
    };
    // A voltage pattern: steps at 1000 r/min, then top speed, so the currents move.
    auto inputs = [&](fmi2Component c, int k) {
        const fmi2ValueReference v[3] = {vr.at("u_d"), vr.at("u_q"), vr.at("w_m")};
        const double w = k < steps / 2 ? 104.7 : 1256.6;
        const double val[3] = {k % 50 < 25 ? -10.0 : -30.0, (k % 50 < 25 ? 10.0 : -5.0) + 0.312 * w, w};
        CHECK(api.fmi2SetReal(c, v, 3, val) == fmi2OK);
    };
    auto run = [&](fmi2Component c, int from, int to, std::vector<double>* trace) {
        for (int k = from; k < to; ++k) {
            inputs(c, k);
            CHECK(api.fmi2DoStep(c, k * h, h, fmi2True) <= fmi2Warning);
            std::vector<double> y(outs.size());
            CHECK(api.fmi2GetReal(c, out_vr.data(), out_vr.size(), y.data()) == fmi2OK);
            for (double x : y) CHECK(std::isfinite(x));
            if (trace) trace->insert(trace->end(), y.begin(), y.end());
        }
    };

    // 1. run, reset, run again, terminate, free
    {
        fmi2Component c = make("plant1");
        init(c);
        std::vector<double> a, b;
        run(c, 0, steps, &a);
        CHECK(api.fmi2Reset(c) == fmi2OK);
        init(c);
        run(c, 0, steps, &b);
        CHECK(a == b);  // a fresh start after reset reproduces the first run exactly
        CHECK(api.fmi2Terminate(c) == fmi2OK);
        api.fmi2FreeInstance(c);
        std::printf("1. run, reset, run, terminate, free: done\n");
    }
    // 2. free without terminate
    {
        fmi2Component c = make("plant2");
        init(c);
        run(c, 0, steps / 2, nullptr);
        api.fmi2FreeInstance(c);
        std::printf("2. free without terminate: done\n");
    }
    // 3. FMU states
    {
        fmi2Component c = make("plant3");
        init(c);
        run(c, 0, steps / 2, nullptr);
        fmi2FMUstate s = nullptr;
        CHECK(api.fmi2GetFMUstate(c, &s) == fmi2OK);
        std::vector<double> a, b, d;
        run(c, steps / 2, steps, &a);
        CHECK(api.fmi2SetFMUstate(c, s) == fmi2OK);
        run(c, steps / 2, steps, &b);
        CHECK(a == b);
        std::size_t n = 0;
        CHECK(api.fmi2SerializedFMUstateSize(c, s, &n) == fmi2OK);
        std::vector<fmi2Byte> bytes(n);
        CHECK(api.fmi2SerializeFMUstate(c, s, bytes.data(), n) == fmi2OK);
        fmi2Component c2 = make("plant3b");  // a fresh instance, not initialised
        fmi2FMUstate s2 = nullptr;
        CHECK(api.fmi2DeSerializeFMUstate(c2, bytes.data(), n, &s2) == fmi2OK);
        CHECK(api.fmi2SetFMUstate(c2, s2) == fmi2OK);
        run(c2, steps / 2, steps, &d);
        CHECK(a == d);
        fmi2FMUstate s3 = nullptr;
        CHECK(api.fmi2GetFMUstate(c, &s3) == fmi2OK);  // left alive: freed with the instance
        CHECK(api.fmi2FreeFMUstate(c, &s) == fmi2OK);
        api.fmi2FreeInstance(c);
        api.fmi2FreeInstance(c2);  // s2 still alive
        std::printf("3. FMU states and serialisation: done\n");
    }
    // 4. errors
    {
        fmi2Component c = make("plant4");
        CHECK(api.fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK);
        CHECK(api.fmi2EnterInitializationMode(c) == fmi2OK);
        const fmi2ValueReference map_vr = vr.at("flux_map");
        const fmi2String missing = "/nonexistent/map.csv";
        CHECK(api.fmi2SetString(c, &map_vr, 1, &missing) == fmi2OK);
        CHECK(api.fmi2ExitInitializationMode(c) == fmi2Error);
        CHECK(last_log.find("nonexistent") != std::string::npos);
        api.fmi2FreeInstance(c);

        c = make("plant5");
        init(c);
        const fmi2ValueReference u = vr.at("u_d");
        const double nan = std::nan("");
        CHECK(api.fmi2SetReal(c, &u, 1, &nan) == fmi2Error);
        const fmi2ValueReference ms = vr.at("cvode_max_steps");
        const fmi2Integer one = 1, many = 20000;
        CHECK(api.fmi2SetInteger(c, &ms, 1, &one) == fmi2OK);
        const fmi2ValueReference uv[2] = {vr.at("u_q"), vr.at("w_m")};
        const double uval[2] = {150.0, 1256.6};
        CHECK(api.fmi2SetReal(c, uv, 2, uval) == fmi2OK);
        CHECK(api.fmi2DoStep(c, 0.0, h, fmi2True) == fmi2Error);
        CHECK(last_log.find("mxstep") != std::string::npos);
        CHECK(api.fmi2SetInteger(c, &ms, 1, &many) == fmi2OK);
        CHECK(api.fmi2DoStep(c, 0.0, h, fmi2True) == fmi2OK);
        api.fmi2FreeInstance(c);
        std::printf("4. errors: done\n");
    }
    // 5. two instances interleaved
    {
        fmi2Component a = make("plantA");
        fmi2Component b = make("plantB");
        init(a);
        init(b);
        std::vector<double> ta, tb;
        for (int k = 0; k < steps; ++k) {
            run(a, k, k + 1, &ta);
            run(b, k, k + 1, &tb);
        }
        CHECK(ta == tb);
        api.fmi2FreeInstance(a);
        api.fmi2FreeInstance(b);
        std::printf("5. two instances: done\n");
    }
    // No dlclose: the FMU links libstdc++ statically, whose emergency exception-handling pool
    // (72 704 bytes, allocated once when the library is loaded) would then be reported as
    // "definitely lost" although it belongs to no instance. Loaded, it is "still reachable".
    std::printf("%s (%d failed checks)\n", check::failures == 0 ? "OK" : "FAILED", check::failures);
    return check::failures == 0 ? 0 : 1;
}
