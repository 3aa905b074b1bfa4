// The parts' variable tables; see part_variables.hpp.
#include "parts/part_variables.hpp"

#include <limits>

#include "machine/flux_map.hpp"
#include "machine/machine.hpp"

namespace ipmsm {

using fmi::Causality;
using fmi::Variability;

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
}  // namespace

namespace {
// An array of MotorParams held behind its shared pointer (an empty array while there is none).
fmi::Access<MotorParams, std::vector<double>> map_array(MotorParams::Values MotorParams::*values) {
    return {[values](const MotorParams& p) { return p.*values ? *(p.*values) : std::vector<double>{}; },
            [values](MotorParams& p, const std::vector<double>& x) {
                p.*values = std::make_shared<const std::vector<double>>(x);
            }};
}
}  // namespace

const std::vector<fmi::Variable<MotorParams>>& variables_of(const MotorParams*) {
    using P = MotorParams;
    // FMI 3.0 only (variable.hpp, fmi3_only): the map as arrays, an alternative to flux_map.
    constexpr double kAxisMax = static_cast<double>(kMaxGridAxis);
    static const std::vector<fmi::Variable<P>> table = {
        {"flux_map", &P::flux_map, Causality::parameter, Variability::fixed, "", "",
         "Path of a flux-map CSV (the contract's format); empty: the default map in resources/"},
        {"pole_pairs", &P::pole_pairs, Causality::parameter, Variability::fixed, "", "", "Pole pairs p (omega = p w_m)",
         1, 100},
        {"R_s", &P::R_s, Causality::parameter, Variability::fixed, "Ohm", "mOhm", "Stator resistance at T_winding_ref",
         0.0, 1e3},
        {"I_max", &P::I_max, Causality::parameter, Variability::fixed, "A", "",
         "Peak current limit of the drive (the controller's): the flux map must be legal in its operating region "
         "(docs/maps.md)",
         0.0, kInf, true},
        {"T_magnet_ref", &P::T_magnet_ref, Causality::parameter, Variability::fixed, "K", "degC",
         "Magnet temperature at which the flux map holds", kTemperatureMin_K, kTemperatureMax_K},
        {"k_psi_T", &P::k_psi_T, Causality::parameter, Variability::fixed, "1/K", "",
         "Relative change of the magnet flux per kelvin (NdFeB about -0.0012)", -0.01, 0.01},
        {"T_winding_ref", &P::T_winding_ref, Causality::parameter, Variability::fixed, "K", "degC",
         "Winding temperature at which R_s holds", kTemperatureMin_K, kTemperatureMax_K},
        {"alpha_cu", &P::alpha_cu, Causality::parameter, Variability::fixed, "1/K", "",
         "Temperature coefficient of the winding resistance (copper 0.00393)", 0.0, 0.01},
        {"n_i_d", &P::n_i_d, Causality::structural_parameter, Variability::fixed, "", "",
         "The flux map as arrays: number of i_d axis values (at most 1 on both axes, the start: no map as arrays, "
         "flux_map holds it)",
         0.0, kAxisMax},
        {"n_i_q", &P::n_i_q, Causality::structural_parameter, Variability::fixed, "", "",
         "The flux map as arrays: number of i_q axis values (at most 1 on both axes, the start: no map as arrays, "
         "flux_map holds it)",
         0.0, kAxisMax},
        {"i_d_axis",
         map_array(&P::i_d_axis),
         Causality::parameter,
         Variability::fixed,
         "A",
         "",
         "The flux map as arrays: the grid's i_d values, each once (peak, amplitude-invariant dq)",
         -kInf,
         kInf,
         false,
         false,
         {"n_i_d"}},
        {"i_q_axis",
         map_array(&P::i_q_axis),
         Causality::parameter,
         Variability::fixed,
         "A",
         "",
         "The flux map as arrays: the grid's i_q values, each once",
         -kInf,
         kInf,
         false,
         false,
         {"n_i_q"}},
        {"psi_d_map",
         map_array(&P::psi_d_map),
         Causality::parameter,
         Variability::fixed,
         "Wb",
         "",
         "The flux map as arrays: psi_d at (i_d_axis[j], i_q_axis[k]), element [j][k]",
         -kInf,
         kInf,
         false,
         false,
         {"n_i_d", "n_i_q"}},
        {"psi_q_map",
         map_array(&P::psi_q_map),
         Causality::parameter,
         Variability::fixed,
         "Wb",
         "",
         "The flux map as arrays: psi_q at (i_d_axis[j], i_q_axis[k]), element [j][k]",
         -kInf,
         kInf,
         false,
         false,
         {"n_i_d", "n_i_q"}},
    };
    return table;
}

const std::vector<fmi::Variable<IronLossModel>>& variables_of(const IronLossModel*) {
    using P = IronLossModel;
    static const std::vector<fmi::Variable<P>> table = {
        {"fe_k_h", &P::k_h, Causality::parameter, Variability::fixed, "J", "",
         "Iron loss: hysteresis coefficient, W/Hz (0: no hysteresis loss)", 0.0, 1e6},
        {"fe_alpha", &P::alpha, Causality::parameter, Variability::fixed, "1", "",
         "Iron loss: exponent of b in the hysteresis term", 0.5, 4.0},
        {"fe_k_e", &P::k_e, Causality::parameter, Variability::fixed, "", "",
         "Iron loss: eddy-current coefficient, W/Hz^2 (0: no eddy-current loss)", 0.0, 1e3},
        {"fe_psi_ref", &P::psi_ref, Causality::parameter, Variability::fixed, "Wb", "",
         "Iron loss: flux linkage at which b = 1", 0.0, 1e3, true},
    };
    return table;
}

const std::vector<fmi::Variable<InverterParams>>& variables_of(const InverterParams*) {
    static const std::vector<fmi::Variable<InverterParams>> table = {
        {"f_sw", &InverterParams::f_sw, Causality::parameter, Variability::fixed, "Hz", "",
         "Inverter switching frequency (continuous PWM)", 0.0, 1e6},
        {"V_T0", &InverterParams::V_T0, Causality::parameter, Variability::fixed, "V", "", "IGBT threshold voltage",
         0.0, 10.0},
        {"r_T", &InverterParams::r_T, Causality::parameter, Variability::fixed, "Ohm", "mOhm", "IGBT slope resistance",
         0.0, 1.0},
        {"V_D0", &InverterParams::V_D0, Causality::parameter, Variability::fixed, "V", "", "Diode threshold voltage",
         0.0, 10.0},
        {"r_D", &InverterParams::r_D, Causality::parameter, Variability::fixed, "Ohm", "mOhm", "Diode slope resistance",
         0.0, 1.0},
        {"E_on", &InverterParams::E_on, Causality::parameter, Variability::fixed, "J", "",
         "IGBT turn-on energy at I_ref, V_ref", 0.0, 100.0},
        {"E_off", &InverterParams::E_off, Causality::parameter, Variability::fixed, "J", "",
         "IGBT turn-off energy at I_ref, V_ref", 0.0, 100.0},
        {"E_rec", &InverterParams::E_rec, Causality::parameter, Variability::fixed, "J", "",
         "Diode reverse-recovery energy at I_ref, V_ref", 0.0, 100.0},
        {"I_ref", &InverterParams::I_ref, Causality::parameter, Variability::fixed, "A", "",
         "Test current of the switching energies", 0.0, kInf, true},
        {"V_ref", &InverterParams::V_ref, Causality::parameter, Variability::fixed, "V", "",
         "Test DC voltage of the switching energies", 0.0, kInf, true},
        {"k_v", &InverterParams::k_v, Causality::parameter, Variability::fixed, "1", "",
         "Exponent of the switching energies' DC-voltage scaling", 0.0, 3.0},
    };
    return table;
}

namespace thermal {

const std::vector<fmi::Variable<LptnParams>>& variables_of(const LptnParams*) {
    static const std::vector<fmi::Variable<LptnParams>> table = {
        {"C_stator_yoke", &LptnParams::C_stator_yoke, Causality::parameter, Variability::fixed, "J/K", "",
         "Thermal network: heat capacity of the stator yoke", 0.0, 1e9, true},
        {"C_stator_tooth", &LptnParams::C_stator_tooth, Causality::parameter, Variability::fixed, "J/K", "",
         "Thermal network: heat capacity of the stator teeth", 0.0, 1e9, true},
        {"C_winding", &LptnParams::C_winding, Causality::parameter, Variability::fixed, "J/K", "",
         "Thermal network: heat capacity of the winding", 0.0, 1e9, true},
        {"C_magnet", &LptnParams::C_magnet, Causality::parameter, Variability::fixed, "J/K", "",
         "Thermal network: heat capacity of the magnets and rotor", 0.0, 1e9, true},
        {"R_yoke_winding", &LptnParams::R_yoke_winding, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: resistance stator yoke - winding", 0.0, 1e6, true},
        {"R_yoke_tooth", &LptnParams::R_yoke_tooth, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: resistance stator yoke - teeth", 0.0, 1e6, true},
        {"R_tooth_winding", &LptnParams::R_tooth_winding, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: resistance teeth - winding", 0.0, 1e6, true},
        {"R_coolant_yoke", &LptnParams::R_coolant_yoke, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: resistance coolant - yoke at 20 degC coolant", 0.0, 1e6, true},
        {"k_coolant_yoke", &LptnParams::k_coolant_yoke, Causality::parameter, Variability::fixed, "1/K", "",
         "Thermal network: R_coolant_yoke's relative change per kelvin of coolant", -1.0, 1.0},
        {"R_tooth_magnet_a", &LptnParams::R_tooth_magnet_a, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: teeth - magnet resistance a exp(-n / b) + c: a", 0.0, 1e6},
        {"R_tooth_magnet_b", &LptnParams::R_tooth_magnet_b, Causality::parameter, Variability::fixed, "1", "",
         "Thermal network: teeth - magnet resistance: b (normalised speed)", 0.0, 1e6, true},
        {"R_tooth_magnet_c", &LptnParams::R_tooth_magnet_c, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: teeth - magnet resistance: c", 0.0, 1e6, true},
        {"R_winding_magnet_a", &LptnParams::R_winding_magnet_a, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: winding - magnet resistance a exp(-n / b) + c: a", 0.0, 1e6},
        {"R_winding_magnet_b", &LptnParams::R_winding_magnet_b, Causality::parameter, Variability::fixed, "1", "",
         "Thermal network: winding - magnet resistance: b (normalised speed)", 0.0, 1e6, true},
        {"R_winding_magnet_c", &LptnParams::R_winding_magnet_c, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: winding - magnet resistance: c", 0.0, 1e6, true},
        {"R_magnet_ambient_a", &LptnParams::R_magnet_ambient_a, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: magnet - ambient resistance a exp(-n / b) + c: a", 0.0, 1e6},
        {"R_magnet_ambient_b", &LptnParams::R_magnet_ambient_b, Causality::parameter, Variability::fixed, "1", "",
         "Thermal network: magnet - ambient resistance: b (normalised speed)", 0.0, 1e6, true},
        {"R_magnet_ambient_c", &LptnParams::R_magnet_ambient_c, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: magnet - ambient resistance: c", 0.0, 1e6, true},
        {"R_magnet_coolant_0", &LptnParams::R_magnet_coolant_0, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: magnet - coolant resistance r0 + r_n n + r_c c + r_nc n c: r0", -1e6, 1e6},
        {"R_magnet_coolant_n", &LptnParams::R_magnet_coolant_n, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: magnet - coolant resistance: r_n", -1e6, 1e6},
        {"R_magnet_coolant_c", &LptnParams::R_magnet_coolant_c, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: magnet - coolant resistance: r_c (c = coolant / 100 degC)", -1e6, 1e6},
        {"R_magnet_coolant_nc", &LptnParams::R_magnet_coolant_nc, Causality::parameter, Variability::fixed, "K/W", "",
         "Thermal network: magnet - coolant resistance: r_nc", -1e6, 1e6},
        {"k_fe_stator_0", &LptnParams::k_fe_stator_0, Causality::parameter, Variability::fixed, "1", "",
         "Thermal network: stator share of the iron loss k0 + k_n n + k_i i + k_ni n i: k0", -10.0, 10.0},
        {"k_fe_stator_n", &LptnParams::k_fe_stator_n, Causality::parameter, Variability::fixed, "1", "",
         "Thermal network: stator share of the iron loss: k_n", -10.0, 10.0},
        {"k_fe_stator_i", &LptnParams::k_fe_stator_i, Causality::parameter, Variability::fixed, "1", "",
         "Thermal network: stator share of the iron loss: k_i (i = I_rms / I_rms_ref)", -10.0, 10.0},
        {"k_fe_stator_ni", &LptnParams::k_fe_stator_ni, Causality::parameter, Variability::fixed, "1", "",
         "Thermal network: stator share of the iron loss: k_ni", -10.0, 10.0},
        {"k_fe_yoke", &LptnParams::k_fe_yoke, Causality::parameter, Variability::fixed, "1", "",
         "Thermal network: the yoke's share of the stator's iron loss (the rest: teeth)", 0.0, 1.0},
        {"w_m_ref", &LptnParams::w_m_ref, Causality::parameter, Variability::fixed, "rad/s", "",
         "Thermal network: speed of n = 1 in its fits", 0.0, 1e5, true},
        {"I_rms_ref", &LptnParams::I_rms_ref, Causality::parameter, Variability::fixed, "A", "",
         "Thermal network: RMS current of i = 1 in its fits", 0.0, 1e6, true},
    };
    return table;
}

}  // namespace thermal
}  // namespace ipmsm
