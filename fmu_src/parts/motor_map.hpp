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

// The map's file: motor.flux_map, or the default map in the FMU's resources/ folder. Throws
// fmi::Error where flux_map is empty and the folder unknown.
std::string flux_map_path(const MotorParams& motor, const fmi::Context& context);

struct MotorMap {
    std::shared_ptr<const FluxMap> map;
    MapAcceptance acceptance;  // where the map is legal (the plant inverts it there)
};

// The map at path: parsed (its errors say file and line), its metadata's disagreements with the
// model's parameters (`parameter`: the model's parameter by name) logged as warnings, accepted
// for the current limit motor.I_max (or fmi::Error naming the defect) and the acceptance's
// warning logged.
MotorMap load_motor_map(const MotorParams& motor, const std::string& path, const fmi::Context& context,
                        const ParameterValue& parameter);

}  // namespace ipmsm
