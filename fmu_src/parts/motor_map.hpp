// The motor's flux map as every model loads it at initialisation: the one place that resolves
// the path, parses (once per content, flux_map_cache.hpp), compares the map's metadata with the
// model's parameters and applies the rule of which maps are accepted (operating_region.hpp).
#pragma once

#include <memory>
#include <string>

#include "machine/flux_map.hpp"
#include "machine/flux_map_metadata.hpp"
#include "machine/motor_params.hpp"
#include "machine/operating_region.hpp"
#include "model.hpp"

namespace ipmsm {

// What messages call a map given as arrays (FMI 3.0: n_i_d, n_i_q, i_d_axis, i_q_axis, psi_d_map,
// psi_q_map), where they would name a map's file.
inline constexpr const char* kMapArrays = "the flux-map arrays (i_d_axis, i_q_axis, psi_d_map, psi_q_map)";

// The map's source: motor.flux_map, or the default map in the FMU's resources/ folder, or
// kMapArrays where the map is given as arrays. Throws fmi::Error where flux_map is empty and the
// folder unknown, or where both flux_map and the arrays give a map.
std::string flux_map_path(const MotorParams& motor, const fmi::Context& context);

struct MotorMap {
    std::shared_ptr<const FluxMap> map;
    MapAcceptance acceptance;  // where the map is legal (the plant inverts it there)
};

// The map at path (or given as arrays, as the contract's text: the same parser): parsed (its errors say file and line), its metadata's disagreements with the
// model's parameters (`parameter`: the model's parameter by name) logged as warnings, accepted
// for the current limit motor.I_max (or fmi::Error naming the defect) and the acceptance's
// warning logged.
MotorMap load_motor_map(const MotorParams& motor, const std::string& path, const fmi::Context& context,
                        const ParameterValue& parameter);

}  // namespace ipmsm
