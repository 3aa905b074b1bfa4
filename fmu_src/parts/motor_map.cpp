#include "parts/motor_map.hpp"

#include <vector>

#include "fmi2_support.hpp"
#include "machine/flux_map_cache.hpp"
#include "machine/map_file.hpp"

namespace ipmsm {

namespace {

// The map given as arrays, as the contract's CSV text: read by the same parser as a file, so the
// same rules, warnings and refusals apply. The numbers are written shortest round-trip
// (std::to_chars): they read back bit for bit.
std::string map_text(const MotorParams& motor) {
    auto values = [](const MotorParams::Values& v) { return v ? *v : std::vector<double>{}; };
    const std::vector<double> d = values(motor.i_d_axis), q = values(motor.i_q_axis), psi_d = values(motor.psi_d_map),
                              psi_q = values(motor.psi_q_map);
    // The glue keeps every array as long as its lengths say; a model built otherwise is refused.
    if (d.size() != motor.n_i_d || q.size() != motor.n_i_q || psi_d.size() != d.size() * q.size() ||
        psi_q.size() != psi_d.size())
        throw fmi::Error(std::string(kMapArrays) + ": the arrays' lengths disagree with n_i_d = " +
                         std::to_string(motor.n_i_d) + ", n_i_q = " + std::to_string(motor.n_i_q));
    std::string text = "i_d,i_q,psi_d,psi_q\n";
    text.reserve(text.size() + psi_d.size() * 4 * 24);
    for (std::size_t j = 0; j < d.size(); ++j)
        for (std::size_t k = 0; k < q.size(); ++k) {
            const std::size_t e = j * q.size() + k;
            text += fmi::number_text(d[j]) + ',' + fmi::number_text(q[k]) + ',' + fmi::number_text(psi_d[e]) + ',' +
                    fmi::number_text(psi_q[e]) + '\n';
        }
    return text;
}

}  // namespace

std::string flux_map_path(const MotorParams& motor, const fmi::Context& context) {
    if (motor.map_as_arrays()) {
        if (!motor.flux_map.empty())
            throw fmi::Error("flux_map = " + quoted_excerpt(motor.flux_map) + " and " + kMapArrays +
                             " both give a flux map: give one (flux_map = \"\", or n_i_d = n_i_q = 1)");
        return kMapArrays;
    }
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
        // parsed once per content
        m.map = motor.map_as_arrays() ? shared_flux_map_text(map_text(motor), path) : shared_flux_map(path);
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
