// Thermal derating of the torque limit, as a drive protects its machine: above a start
// temperature, the torque limit falls linearly to zero at the maximum temperature of the winding
// (its insulation) and of the magnets (their irreversible demagnetisation); the factor is the
// smaller of the two. Each starts derating_margin below its maximum (docs/thermal.md, "Controller").
#pragma once

#include <algorithm>

namespace ipmsm {

struct DeratingLimits {
    double T_winding_max;  // K
    double T_magnet_max;   // K
    double margin;         // K (> 0): derating starts this far below each maximum
};

// The torque limit's factor in [0, 1] at these temperatures (K): exactly 1 at or below both
// start temperatures, 0 at or above either maximum.
inline double thermal_derating(const DeratingLimits& d, double T_winding, double T_magnet) {
    const auto factor = [&](double T, double T_max) { return std::clamp((T_max - T) / d.margin, 0.0, 1.0); };
    return std::min(factor(T_winding, d.T_winding_max), factor(T_magnet, d.T_magnet_max));
}

}  // namespace ipmsm
