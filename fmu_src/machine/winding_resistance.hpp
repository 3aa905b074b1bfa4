// The stator winding's resistance at its temperature: copper's linear law
//     R(T) = R_s (1 + alpha_cu (T - T_winding_ref)),
// R_s the resistance at T_winding_ref. One law for every model that needs it (the plant's
// copper loss and voltage drop, the controller's voltage ellipse and current regulator).
#pragma once

#include <sstream>
#include <string>

#include "machine/machine.hpp"

namespace ipmsm {

// Annealed copper at 20 degC, 1/K (IEC 60028, the international standard of resistance for
// copper: 0.00393 1/K referred to 20 degC).
constexpr double kCopperTemperatureCoefficient = 0.00393;

inline double winding_resistance(double R_s, double alpha_cu, double T_winding, double T_winding_ref) {
    return R_s * (1.0 + alpha_cu * (T_winding - T_winding_ref));
}

// Why the law cannot hold (it makes the resistance negative at an admissible winding temperature,
// kTemperatureMin_K up); empty where it holds.
inline std::string winding_law_error(double alpha_cu, double T_winding_ref) {
    if (alpha_cu * (kTemperatureMin_K - T_winding_ref) > -1.0) return {};
    std::ostringstream os;
    os.precision(10);
    os << "alpha_cu = " << alpha_cu << " 1/K with T_winding_ref = " << T_winding_ref
       << " K makes the resistance negative at admissible winding temperatures";
    return os.str();
}

}  // namespace ipmsm
