// Flux maps psi_d(i_d, i_q), psi_q(i_d, i_q): the contract's CSV format, and a smooth interpolant
// with first and second derivatives (needed by the optimal-current Newton steps and the plant).
#pragma once

#include <iosfwd>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace ipmsm {

struct FluxMapError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// A flux map as tabulated on a full rectangular grid.
struct FluxMapTable {
    std::vector<double> i_d, i_q;      // grid axes, strictly ascending, A (peak)
    std::vector<double> psi_d, psi_q;  // value at (i_d[j], i_q[k]) is at [k * i_d.size() + j], Wb
    std::map<std::string, std::string> metadata;  // from '# key: value' lines

    // A metadata entry as a number, or fallback if absent; throws FluxMapError if not a number.
    double metadata_number(const std::string& key, double fallback) const;
};

// Read the contract's CSV format ('#' lines, header i_d,i_q,psi_d,psi_q, rows in any order).
// Throws FluxMapError naming the file and line for: missing or unreadable file, no header,
// no rows, text in numbers, non-finite values, duplicate points, a grid that is not full and
// rectangular (at least 4 x 4), psi_d not increasing in i_d or psi_q not increasing in i_q.
FluxMapTable read_flux_map(const std::string& path);
FluxMapTable parse_flux_map(std::istream& in, const std::string& source_name);

// The map of a linear machine psi_d = L_d i_d + psi_m, psi_q = L_q i_q on an n x n grid
// spanning [-i_range, i_range] on both axes.
FluxMapTable linear_flux_map(double L_d, double L_q, double psi_m, double i_range, int n);

// Flux linkages and incremental inductances at one current.
struct FluxPoint {
    double psi_d, psi_q;  // Wb
    double L_dd, L_dq;    // d psi_d / d i_d, d psi_d / d i_q, H
    double L_qd, L_qq;    // d psi_q / d i_d, d psi_q / d i_q, H
};

// ... plus second derivatives, H/A.
struct FluxPoint2 : FluxPoint {
    double psi_d_dd, psi_d_dq, psi_d_qq;
    double psi_q_dd, psi_q_dq, psi_q_qq;
};

// C2 bicubic-spline interpolant of a flux map. Outside the grid it extrapolates linearly from
// the nearest boundary point (value and gradient continuous). Immutable and cheap to evaluate.
class FluxMap {
public:
    explicit FluxMap(const FluxMapTable& table);

    FluxPoint eval(double i_d, double i_q) const;
    FluxPoint2 eval2(double i_d, double i_q) const;

    double psi_m() const { return psi_m_; }  // psi_d(0, 0), the PM flux linkage
    double i_d_min() const { return id_.front(); }
    double i_d_max() const { return id_.back(); }
    double i_q_min() const { return iq_.front(); }
    double i_q_max() const { return iq_.back(); }
    const FluxMapTable& table() const { return table_; }

private:
    FluxMapTable table_;
    std::vector<double> id_, iq_;
    // Per cell: 16 bicubic coefficients for psi_d, then 16 for psi_q (implementation detail).
    std::vector<double> coef_;
    bool uniform_d_ = false, uniform_q_ = false;
    double inv_dd_ = 0, inv_dq_ = 0;
    double psi_m_ = 0;
};

}  // namespace ipmsm
