#include "control/torque_table.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace ipmsm {
namespace {

// The flux axis spans psi_s from the value at top speed up to this factor times the stator flux
// at the zero-speed torque peak: above it the drive is in MTPA whatever the torque.
constexpr double kFluxAxisHeadroom = 1.10;

double v_max_of(const TableSpec& s) { return s.k_u * s.u_dc / std::sqrt(3.0); }

// Index and weight of x in an ascending uniform axis, clamped to its ends.
void locate(const std::vector<double>& axis, double x, int& i, double& w) {
    const int n = static_cast<int>(axis.size());
    const double t = (x - axis.front()) / (axis.back() - axis.front()) * (n - 1);
    if (!(t > 0)) {
        i = 0;
        w = 0;
        return;
    }
    if (t >= n - 1) {
        i = n - 2;
        w = 1;
        return;
    }
    i = static_cast<int>(t);
    w = t - i;
}

}  // namespace

TorqueTable::TorqueTable(SaturatedOptimalCurrent solver, const TableSpec& spec)
    : TorqueTable(solver, spec, [&solver, &spec](double T, const OperatingLimits& lim) {
          return solver.solve(T, lim, spec.R_s, spec.psi_d_shift, Recursion::optimal);
      }) {}

TorqueTable::TorqueTable(SaturatedOptimalCurrent solver, const TableSpec& spec, const Entry& entry)
    : spec_(spec), pole_pairs_(solver.pole_pairs()) {
    if (spec.n_torque < 3 || spec.n_second < 3) throw std::invalid_argument("2-D table needs at least 3 x 3 points");
    if (!(spec.u_dc > 0) || !(spec.I_max > 0) || !(spec.w_m_max > 0))
        throw std::invalid_argument("2-D table: u_dc, I_max and the top speed must be positive");
    const double V_max = v_max_of(spec);
    const int p = pole_pairs_;

    // Torque axis from the zero-speed peak (MTPA at I_max).
    const CurrentCommand peak =
        solver.solve(1e12, {0.0, V_max, spec.I_max}, spec.R_s, spec.psi_d_shift, Recursion::optimal);
    T_peak_ = peak.torque_max;

    // Second axis.
    x_.resize(spec.n_second);
    if (spec.axis == TableAxis::speed) {
        for (int j = 0; j < spec.n_second; ++j) x_[j] = spec.w_m_max * j / (spec.n_second - 1);
    } else {
        const MagnetFlux flux(solver.map(), spec.psi_d_shift);
        const FluxPoint f = flux.eval(peak.i_d, peak.i_q);
        const double psi_lo = V_max / (p * spec.w_m_max);
        const double psi_hi = kFluxAxisHeadroom * std::hypot(f.psi_d, f.psi_q);
        for (int j = 0; j < spec.n_second; ++j) x_[j] = psi_lo + (psi_hi - psi_lo) * j / (spec.n_second - 1);
    }

    // Entries: recursion 2 (or `entry`) at every node (its answer depends on the node only).
    const std::size_t n = static_cast<std::size_t>(spec.n_torque) * spec.n_second;
    i_d_.assign(n, 0.0);
    i_q_.assign(n, 0.0);
    region_.assign(n, 0);
    T_max_pos_.assign(spec.n_second, 0.0);
    T_max_neg_.assign(spec.n_second, 0.0);
    for (int j = 0; j < spec.n_second; ++j) {
        const double omega = spec.axis == TableAxis::speed ? p * x_[j] : V_max / x_[j];
        const OperatingLimits lim{omega, V_max, spec.I_max};
        for (int k = 0; k < spec.n_torque; ++k) {
            const double T = T_peak_ * (2.0 * k / (spec.n_torque - 1) - 1.0);
            const CurrentCommand c = entry(T, lim);
            const std::size_t at = static_cast<std::size_t>(j) * spec.n_torque + k;
            i_d_[at] = c.i_d;
            i_q_[at] = c.i_q;
            region_[at] = static_cast<signed char>(c.region);
            (T < 0 ? T_max_neg_ : T_max_pos_)[j] = c.torque_max;
        }
    }
}

double TorqueTable::second_coordinate(double omega_abs, double V_max) const {
    if (spec_.axis == TableAxis::speed) return omega_abs / pole_pairs_;
    return omega_abs > 0 ? V_max / omega_abs : x_.back();
}

CurrentCommand TorqueTable::lookup(double T_ref, double w_m, double V_max) const {
    // Mirror negative speed: (T, omega, i_q) -> (-T, -omega, -i_q).
    const double mirror = w_m < 0 ? -1.0 : 1.0;
    const double T = mirror * T_ref;
    const double x = second_coordinate(std::abs(w_m) * pole_pairs_, V_max);
    int j;
    double wx;
    locate(x_, x, j, wx);
    const double T_max_pos = (1 - wx) * T_max_pos_[j] + wx * T_max_pos_[j + 1];
    const double T_max_neg = (1 - wx) * T_max_neg_[j] + wx * T_max_neg_[j + 1];
    const double T_cmd = std::clamp(T, -T_max_neg, T_max_pos);

    const int nt = spec_.n_torque;
    const double t = (T_cmd + T_peak_) / (2.0 * T_peak_) * (nt - 1);
    const int k = std::clamp(static_cast<int>(t), 0, nt - 2);
    const double wt = std::clamp(t - k, 0.0, 1.0);
    auto bilinear = [&](const std::vector<double>& v) {
        const std::size_t a = static_cast<std::size_t>(j) * nt + k, b = a + nt;
        return (1 - wx) * ((1 - wt) * v[a] + wt * v[a + 1]) + wx * ((1 - wt) * v[b] + wt * v[b + 1]);
    };
    CurrentCommand c;
    c.i_d = bilinear(i_d_);
    c.i_q = mirror * bilinear(i_q_);
    const std::size_t nearest = static_cast<std::size_t>(j + (wx > 0.5)) * nt + k + (wt > 0.5);
    c.region = static_cast<Region>(region_[nearest]);
    c.torque = mirror * T_cmd;  // what the table was asked for; the achieved torque is the plant's
    c.torque_max = T_ref * mirror >= 0 ? T_max_pos : T_max_neg;
    return c;
}

std::size_t TorqueTable::bytes() const {
    return (i_d_.size() + i_q_.size() + x_.size() + T_max_pos_.size() + T_max_neg_.size()) * sizeof(double) +
           region_.size() * sizeof(signed char);
}

}  // namespace ipmsm
