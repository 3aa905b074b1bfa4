// The motor as the controller and the plant both know it: its flux map and what the map does
// not hold (pole pairs, resistance and its temperature law, the magnets' temperature law, the
// drive's current limit). One struct, held by each model; its FMI variables are declared once
// (parts/part_variables.cpp) and IpmsmDrive forwards it as a unit. Defaults: the default motor
// (fmu_src/resources/ev_ipmsm_default.csv, whose metadata state the same values).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

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

    // The map itself instead of flux_map (FMI 3.0's array parameters, docs/spec/INTERFACE.md):
    // the axes' lengths, the axes (A) and the fluxes (Wb) at (i_d_axis[j], i_q_axis[k]), element
    // j * n_i_q + k. Shared: the model is copied every step. They start at one element each, a
    // zero: FMI 3.0 wants no array empty at its start (fmi-standard, "Array Variables": initial
    // dimension sizes are positive), and a grid of at most one point per axis is no map, so the
    // map is given as arrays where a length is above 1.
    using Values = std::shared_ptr<const std::vector<double>>;
    std::uint64_t n_i_d = 1, n_i_q = 1;
    Values i_d_axis = one_zero(), i_q_axis = one_zero(), psi_d_map = one_zero(), psi_q_map = one_zero();
    bool map_as_arrays() const { return n_i_d > 1 || n_i_q > 1; }

    static constexpr const char* default_flux_map = "ev_ipmsm_default.csv";

    // The arrays' start: one zero.
    static Values one_zero() {
        static const Values zero = std::make_shared<const std::vector<double>>(1, 0.0);
        return zero;
    }

    // The winding's resistance at T_winding (winding_resistance.hpp), Ohm.
    double resistance(double T_winding) const { return winding_resistance(R_s, alpha_cu, T_winding, T_winding_ref); }
};

}  // namespace ipmsm
