// The 2-D lookup-table method (the seed's baseline, what industry ships): optimal currents
// precomputed offline on a grid and bilinearly interpolated online.
//   method 2 (speed axis): torque x mechanical speed, valid for the u_dc it was built at;
//   method 3 (flux axis):  torque x psi_s = V_max / |omega|, one table for every u_dc.
// Both hold for one magnet temperature. Entries come from the exact solver (recursion 2), and a
// 1-D table of T_max along the second axis clamps the command. Negative speed uses the mirror
// symmetry (T, omega, i_q) -> (-T, -omega, -i_q).
#pragma once

#include <functional>

#include <cstddef>
#include <vector>

#include "control/saturated_optimal_current.hpp"
#include "machine/machine.hpp"

namespace ipmsm {

enum class TableAxis { speed, flux };

struct TableSpec {
    TableAxis axis = TableAxis::speed;
    int n_torque = 41;       // grid points along torque (odd: includes T = 0)
    int n_second = 41;       // grid points along speed or psi_s
    double u_dc = 0;         // V, the DC voltage the table is built for
    double k_u = 0.95;       // V_max = k_u u_dc / sqrt(3)
    double I_max = 0;        // A
    double R_s = 0;          // Ohm
    double psi_d_shift = 0;  // magnet temperature the table is built for (magnet_flux_shift)
    double w_m_max = 0;      // rad/s, top of the speed axis
};

class TorqueTable {
public:
    // Builds the table with the exact solver (a copy; its warm starts walk the grid).
    TorqueTable(SaturatedOptimalCurrent solver, const TableSpec& spec);
    // ... with the entries from `entry` (the command for a torque at a node's limits, its
    // torque_max included): the least-loss tables (objective 1), made from the least-loss solver
    // at the table's u_dc and magnet temperature, as SyR-e makes its maximum-efficiency maps.
    using Entry = std::function<CurrentCommand(double T, const OperatingLimits& lim)>;
    TorqueTable(SaturatedOptimalCurrent solver, const TableSpec& spec, const Entry& entry);

    // The command for T_ref at mechanical speed w_m and the present V_max (method 3 uses it).
    CurrentCommand lookup(double T_ref, double w_m, double V_max) const;

    std::size_t bytes() const;  // memory of the stored tables
    const TableSpec& spec() const { return spec_; }

private:
    double second_coordinate(double omega_abs, double V_max) const;  // speed or psi_s, clamped

    TableSpec spec_;
    int pole_pairs_;
    double T_peak_;                  // torque axis spans [-T_peak, T_peak]
    std::vector<double> x_;          // second axis (ascending)
    std::vector<double> i_d_, i_q_;  // [j * n_torque + k]: torque k, second coordinate j
    std::vector<signed char> region_;
    std::vector<double> T_max_pos_, T_max_neg_;  // per second coordinate, >= 0
};

}  // namespace ipmsm
