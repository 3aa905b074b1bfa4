#include "parts/motor_map.hpp"

#include "machine/flux_map_cache.hpp"

namespace ipmsm {

std::string flux_map_path(const MotorParams& motor, const fmi::Context& context) {
    if (motor.flux_map.empty() && context.resource_dir.empty())
        throw fmi::Error(
            "flux_map is empty and the FMU's resources/ folder is unknown (fmuResourceLocation): "
            "set flux_map to a flux-map CSV");
    return motor.flux_map.empty() ? context.resource_dir + "/" + MotorParams::default_flux_map : motor.flux_map;
}

MotorMap load_motor_map(const MotorParams& motor, const std::string& path, const fmi::Context& context,
                        const ParameterValue& parameter) {
    MotorMap m;
    try {
        m.map = shared_flux_map(path);  // parsed once per content
    } catch (const FluxMapError& e) {
        throw fmi::Error(e.what());  // says file and line
    }
    // The map's metadata describes its motor; the parameters rule, but say so when they differ.
    if (context.log_warning)
        for (const std::string& w : metadata_warnings(m.map->table(), path, parameter)) context.log_warning(w);
    try {
        m.acceptance = accept_flux_map(*m.map, motor.I_max, path);  // legal where the drive operates
    } catch (const FluxMapError& e) {
        throw fmi::Error(e.what());
    }
    if (context.log_warning && !m.acceptance.warning.empty()) context.log_warning(m.acceptance.warning);
    return m;
}

}  // namespace ipmsm
