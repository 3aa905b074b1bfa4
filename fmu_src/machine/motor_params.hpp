// The motor as the controller and the plant both know it: its flux map and what the map does
// not hold (pole pairs, resistance and its temperature law, the magnets' temperature law, the
// drive's current limit). One struct, held by each model; its FMI variables are declared once
// (parts/part_variables.cpp) and IpmsmDrive forwards it as a unit. Defaults: the default motor
// (fmu_src/resources/ev_ipmsm_default.csv, whose metadata state the same values).
#pragma once

#include <string>

#include "machine/winding_resistance.hpp"

namespace ipmsm {

struct MotorParams {
    std::string flux_map;  // path of a flux-map CSV; "" = the FMU's resources/ev_ipmsm_default.csv
    int pole_pairs = 4;
    double R_s = 0.012;                               // Ohm at T_winding_ref
    double I_max = 500.0;                             // A, the drive's peak current limit
    double T_magnet_ref = 293.15;                     // K, the magnet temperature the map holds at
    double k_psi_T = -0.0012;                         // 1/K, relative change of the magnet flux
    double T_winding_ref = 293.15;                    // K, the winding temperature R_s holds at
    double alpha_cu = kCopperTemperatureCoefficient;  // 1/K

    static constexpr const char* default_flux_map = "ev_ipmsm_default.csv";

    // The winding's resistance at T_winding (winding_resistance.hpp), Ohm.
    double resistance(double T_winding) const { return winding_resistance(R_s, alpha_cu, T_winding, T_winding_ref); }
};

}  // namespace ipmsm
