// The C++ drivers of libipmsm_cosim (cosim_check, bench/cosim_profile, bench/bench_plant): a
// master on the drive's coupling description (fmu_src/coupling/ipmsm_drive.coupling, embedded
// at build time), both units instantiated from their unzipped folders and initialised.
#pragma once

#include <string>
#include <vector>

#include "cosim.h"
#include "coupling/drive_coupling_text.hpp"
#include "fmu_binary.hpp"

namespace cosim_tools {

using fmu_binary::Description;
using fmu_binary::read_description;

// The drive's outputs as scenarios/master.py's Sample reports them (its SAMPLE_SOURCES, in order).
// clang-format off
inline const std::vector<const char*> kDriveOutputs = {
    "plant.T_shaft", "plant.T_e", "plant.P_elec", "plant.P_mech", "plant.P_cu", "plant.P_fe",
    "plant.i_d", "plant.i_q", "|i|", "|i|^2", "controller.T_cmd", "controller.T_max",
    "controller.region", "controller.iterations", "controller.u_ratio"};
// clang-format on

// Position of `name` in `names` (names.size() if absent).
inline size_t index_of(const std::vector<const char*>& names, const std::string& name) {
    size_t i = 0;
    while (i < names.size() && name != names[i]) ++i;
    return i;
}

// Where the units come from, and their instance names.
struct Units {
    std::string controller_dir, plant_dir;  // unzipped FMUs
    std::string controller_name = "controller", plant_name = "plant";
};

// A master on the drive's coupling at step h, both units instantiated, in Initialization Mode
// with parameters(m) (which returns 0 or the first failing call's -1), initialised with `start`
// (a flying start at start.w_m) and reporting `probes` (cosim.h). nullptr and why on failure.
template <class Parameters>
ipmsm_cosim* start_drive(const Units& units, double h, const ipmsm_cosim_inputs& start,
                         const std::vector<const char*>& probes, std::string& why, Parameters&& parameters,
                         ipmsm_cosim_log_fn log = nullptr) {
    ipmsm_cosim* m = ipmsm_cosim_new(ipmsm::coupling::kDriveCouplingText, h, log, nullptr);
    if (m == nullptr) {
        why = "ipmsm_cosim_new refused h";
        return nullptr;
    }
    int rc = ipmsm_cosim_instantiate(m, "controller", units.controller_dir.c_str(), units.controller_name.c_str(), 0);
    if (rc == 0) rc = ipmsm_cosim_instantiate(m, "plant", units.plant_dir.c_str(), units.plant_name.c_str(), 0);
    if (rc == 0) rc = ipmsm_cosim_enter_initialization(m);
    if (rc == 0) rc = parameters(m);
    if (rc == 0) rc = ipmsm_cosim_initialize(m, &start);
    if (rc == 0) rc = ipmsm_cosim_probes(m, probes.size(), probes.data());
    if (rc != 0) {
        why = ipmsm_cosim_error(m);
        ipmsm_cosim_free(m);
        return nullptr;
    }
    return m;
}

inline ipmsm_cosim* start_drive(const Units& units, double h, const ipmsm_cosim_inputs& start,
                                const std::vector<const char*>& probes, std::string& why) {
    return start_drive(units, h, start, probes, why, [](ipmsm_cosim*) { return 0; });
}

}  // namespace cosim_tools
