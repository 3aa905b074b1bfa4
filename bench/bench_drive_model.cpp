// The IpmsmDrive's own work over a drive cycle, without Python or FMI: DriveModel (the FMU's
// model, fmu_src/drive) stepped at 10 ms over a recorded profile of its inputs (T_ref, w_m, u_dc
// per vehicle step: bench/record_drive_profile.py), as the scenarios' drive backend steps it.
// Reports microseconds per inner step (sample_time, 100 us) for
//   model   DriveModel::do_step alone
//   glue    plus what the FMI glue adds per communication step: the undo copy of the model
// (best of `rounds` runs) and the run's integrals, so that two builds can be compared.
//
//   bench_drive_model <profile.csv> [rounds = 3] [seconds = all] [from = 0 s] [thermal = 0]
// (thermal 1: with the plant's thermal network, thermal_model, from the nominal temperature)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "drive/drive_model.hpp"
#include "source_tree.hpp"

namespace {

struct Row {
    double T_ref, w_m, u_dc;
};

std::vector<Row> read_profile(const char* path) {
    std::ifstream f(path);
    if (!f) {
        std::fprintf(stderr, "cannot read %s (make it with bench/record_drive_profile.py)\n", path);
        std::exit(2);
    }
    std::vector<Row> rows;
    std::string line;
    while (std::getline(f, line)) {
        if (line.empty() || line[0] == '#' || line[0] == 'T') continue;
        std::replace(line.begin(), line.end(), ',', ' ');
        std::istringstream is(line);
        Row r{};
        if (is >> r.T_ref >> r.w_m >> r.u_dc) rows.push_back(r);
    }
    return rows;
}

constexpr double kVehicleStep = 0.01;    // s
constexpr double kTemperature = 293.15;  // K: the scenarios' nominal conditions

struct Result {
    double seconds = 0;
    ipmsm::DriveModel end{fmi::Context{}};
};

bool g_thermal = false;  // thermal_model (argument 5)

Result run(const std::vector<Row>& rows, bool glue_copy) {
    fmi::Context ctx;
    ctx.instance_name = "bench";
    ctx.resource_dir = ipmsm::source_path("fmu_src/resources");
    ipmsm::DriveModel d(ctx);
    d.T_ref = rows[0].T_ref, d.w_m = rows[0].w_m, d.u_dc = rows[0].u_dc;
    d.T_magnet = d.T_winding = kTemperature;
    d.T_coolant = d.T_ambient = kTemperature;
    std::get<fmi::Access<ipmsm::DriveModel, bool>>(fmi::find_variable<ipmsm::DriveModel>("thermal_model")->member)
        .write(d, g_thermal);
    d.exit_initialization();
    ipmsm::DriveModel undo = d;
    const auto t0 = std::chrono::steady_clock::now();
    double t = 0;
    for (const Row& r : rows) {
        d.T_ref = r.T_ref, d.w_m = r.w_m, d.u_dc = r.u_dc;
        if (glue_copy) undo = d;
        d.do_step(t, kVehicleStep);
        t += kVehicleStep;
    }
    const auto t1 = std::chrono::steady_clock::now();
    Result res;
    res.seconds = std::chrono::duration<double>(t1 - t0).count();
    res.end = d;
    return res;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: bench_drive_model <profile.csv> [rounds = 3] [seconds = all] [from = 0 s]\n");
        return 2;
    }
    std::vector<Row> rows = read_profile(argv[1]);
    const int rounds = argc > 2 ? std::atoi(argv[2]) : 3;
    if (argc > 4) {
        const auto from = std::min(rows.size(), static_cast<std::size_t>(std::atof(argv[4]) / kVehicleStep));
        rows.erase(rows.begin(), rows.begin() + static_cast<std::ptrdiff_t>(from));
    }
    if (argc > 3) rows.resize(std::min(rows.size(), static_cast<std::size_t>(std::atof(argv[3]) / kVehicleStep)));
    if (rows.empty()) return 2;
    g_thermal = argc > 5 && std::atoi(argv[5]) != 0;
    const double inner = rows.size() * std::llround(kVehicleStep / 1e-4);
    for (const bool glue : {false, true}) {
        double best = 1e300;
        Result last;
        for (int k = 0; k < rounds; ++k) {
            Result r = run(rows, glue);
            best = std::min(best, r.seconds);
            last = std::move(r);
        }
        const ipmsm::DriveModel& e = last.end;
        std::printf("%-6s %zu steps of 10 ms (%.0f inner): %.3f s, %.3f us per inner step (best of %d)\n",
                    glue ? "glue" : "model", rows.size(), inner, best, 1e6 * best / inner, rounds);
        if (!glue)
            std::printf(
                "       E_dc %.17g J, E_mech %.17g J, E_cu %.17g J, E_fe %.17g J, E_inv %.17g J; winding %.3f K\n",
                e.E_dc, e.E_mech, e.E_cu, e.E_fe, e.E_inv,
                fmi::value_of<double>(e, *fmi::find_variable<ipmsm::DriveModel>("theta_winding")));
    }
    return 0;
}
