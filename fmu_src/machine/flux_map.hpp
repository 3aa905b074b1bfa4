// Flux maps psi_d(i_d, i_q), psi_q(i_d, i_q): the contract's CSV format, and a smooth interpolant
// with first and second derivatives (needed by the optimal-current Newton steps and the plant).
#pragma once

#include <cstddef>
#include <cstdint>
#include <iosfwd>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "numerics/bicubic_spline.hpp"

namespace ipmsm {

struct FluxMapError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// The reader's limits, checked before anything is allocated for them: a grid of at most
// kMaxGridAxis x kMaxGridAxis points (FEM and measured maps have some 20 to 200 per axis; the
// spline of the largest grid takes 64 MiB), lines of at most kMaxLineChars characters, files of
// at most kMaxMapFileBytes (map_file.hpp).
inline constexpr std::size_t kMaxGridAxis = 512;
inline constexpr std::size_t kMaxGridPoints = kMaxGridAxis * kMaxGridAxis;
inline constexpr std::size_t kMaxLineChars = 4096;

// A metadata value "<number> <rest>": "4 (8 poles)" is 4 and "(8 poles)", "12 mOhm" 12 and
// "mOhm"; is_number is false when the text does not start with a finite number.
struct MetadataValue {
    bool is_number = false;
    double value = 0.0;
    std::string rest;
};
MetadataValue split_metadata_value(const std::string& text);

// 64-bit FNV-1a of a file's bytes: what an FMU state records of the map it was saved on.
std::uint64_t content_hash(const std::string& bytes);

// A flux map as tabulated on a full rectangular grid.
struct FluxMapTable {
    std::vector<double> i_d, i_q;                 // grid axes, strictly ascending, A (peak)
    std::vector<double> psi_d, psi_q;             // value at (i_d[j], i_q[k]) is at [k * i_d.size() + j], Wb
    std::map<std::string, std::string> metadata;  // from '# key: value' lines
    std::uint64_t content_hash = 0;               // of the text read; 0 for a table made in memory

    // A metadata entry's leading number (trailing words ignored), or fallback if absent; throws
    // FluxMapError if the entry does not start with a number.
    double metadata_number(const std::string& key, double fallback) const;
};

// Read the contract's CSV format ('#' lines, header i_d,i_q,psi_d,psi_q, rows in any order).
// Throws FluxMapError naming the file and line for: missing or unreadable file, no header,
// no rows, text in numbers, non-finite values, duplicate points, a grid that is not full and
// rectangular (at least 4 x 4). Not monotone grid lines are read: whether they matter depends on
// where the drive operates (operating_region.hpp: accept_flux_map, the FMUs' rule).
// Also refused, before anything large is allocated: a path that is not a regular file (a
// directory, a FIFO, a device: refused at once, map_file.hpp), more than kMaxMapFileBytes,
// kMaxLineChars in a line, kMaxGridPoints rows or kMaxGridAxis values on an axis, a UTF-16 file.
// Inputs echoed in messages are cut to a few hundred characters and escaped to valid UTF-8.
// Accepted: LF, CRLF and CR line ends, blank lines, spaces/tabs around values, a UTF-8 byte-order mark, '#' lines
// anywhere, a leading '+'. Numbers are parsed independently of the C locale and must be
// consumed whole. '# key: value' lines (key: letters, digits, _ . -, starting with a letter or
// _) become metadata; a repeated key keeps the last value. Axis values closer than 1e-9 of the
// axis' span are the same node.
FluxMapTable read_flux_map(const std::string& path);
FluxMapTable parse_flux_map(std::istream& in, const std::string& source_name);
FluxMapTable parse_flux_map_text(const std::string& text, const std::string& source_name);

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
//
// Details (bicubic_spline.hpp): tensor-product cubic spline with not-a-knot end conditions,
// exact for linear (indeed bicubic) data. Outside the grid each edge cell's cubic is continued
// by its tangent: beyond an edge psi(i_b) + dpsi/di_n (i_n - i_b) with i_b the nearest boundary
// point, beyond a corner the bilinear continuation of the corner's value, gradient and cross
// derivative. Values and first derivatives are continuous everywhere, the second derivative
// along the outward normal is zero outside, and all derivatives returned (inductances, second
// derivatives) are the exact derivatives of the values returned, inside and outside; eval and
// eval2 agree bit for bit. Caution: continued linearly along the outward normal, an edge's
// tangential variation grows with distance (beyond the i_q edge, d psi_d / d i_d =
// L_dd(i_b) + dL_dd/di_q (i_q - i_q,b)), so far outside a strongly cross-saturated map the
// continuation can lose monotonicity (Baldor: L_dd < 0 some 9 A beyond its +-26 A i_q edge).
// Keep the operating range inside the map. (The plant does not invert this continuation but one
// that cannot fold: InverseFluxMap::forward_eval, inverse_flux_map.hpp.)
// A FluxMap may also be built from a table with as few as 2 x 2 points (linear_flux_map with
// n = 2); read_flux_map requires 4 x 4.
class FluxMap {
public:
    // Throws FluxMapError if the table's axes are not strictly ascending (>= 2 nodes each), the
    // value arrays do not match the axes, or a value is not finite.
    explicit FluxMap(const FluxMapTable& table);

    FluxPoint eval(double i_d, double i_q) const;
    FluxPoint2 eval2(double i_d, double i_q) const;

    double psi_m() const { return psi_m_; }  // psi_d(0, 0), the PM flux linkage
    double i_d_min() const { return spline_.x().front(); }
    double i_d_max() const { return spline_.x().back(); }
    double i_q_min() const { return spline_.y().front(); }
    double i_q_max() const { return spline_.y().back(); }
    const FluxMapTable& table() const { return table_; }
    const BicubicSpline2D& spline() const { return spline_; }  // fields 0: psi_d, 1: psi_q

private:
    FluxMapTable table_;
    BicubicSpline2D spline_;  // x = i_d, y = i_q; per cell 16 coefficients for psi_d, then psi_q
    double psi_m_ = 0;
};

// What an FMU state records of the map it was saved on: the content hash of its file (0: no map
// loaded, or a map made in memory). A state restored onto another map would continue silently on
// data it was not computed with.
enum class MapContent : std::uint64_t {};
inline MapContent map_content(const FluxMap* map) { return MapContent{map != nullptr ? map->table().content_hash : 0}; }
// Throws FluxMapError if a state saved on `saved` is restored where `map` is loaded.
void check_map_content(MapContent saved, const FluxMap* map);

// The box a map's grid spans: currents (A) and flux linkages (Wb), [lowest, highest] each, and the
// largest flux magnitude |psi| on the grid. What an FMU state's currents and fluxes are checked
// against (a state is input: its values must be ones the machine on this map can have).
struct MapSpan {
    double i_d[2], i_q[2], psi_d[2], psi_q[2];
    double psi_abs_max;
};
MapSpan map_span(const FluxMapTable& table);
// The largest |psi| (Wb) a machine on the map reaches with its currents within the grid: the
// grid's largest, the spline's overshoot between grid points (kSplineReach of it: a C2 cubic
// through monotone data stays well inside half its range again) and the magnets' temperature
// shift |k_psi_T| psi_m over the whole accepted temperature range (machine.hpp).
inline constexpr double kSplineReach = 1.5;
double flux_reach(const MapSpan& span, double psi_m, double k_psi_T);

inline FluxPoint FluxMap::eval(double i_d, double i_q) const {
    SplineValue s[2];
    spline_.eval<2>(i_d, i_q, s);
    return FluxPoint{s[0].f, s[1].f, s[0].fx, s[0].fy, s[1].fx, s[1].fy};
}

inline FluxPoint2 FluxMap::eval2(double i_d, double i_q) const {
    SplineValue2 s[2];
    spline_.eval2<2>(i_d, i_q, s);
    FluxPoint2 r;
    r.psi_d = s[0].f;
    r.psi_q = s[1].f;
    r.L_dd = s[0].fx;
    r.L_dq = s[0].fy;
    r.L_qd = s[1].fx;
    r.L_qq = s[1].fy;
    r.psi_d_dd = s[0].fxx;
    r.psi_d_dq = s[0].fxy;
    r.psi_d_qq = s[0].fyy;
    r.psi_q_dd = s[1].fxx;
    r.psi_q_dq = s[1].fxy;
    r.psi_q_qq = s[1].fyy;
    return r;
}

}  // namespace ipmsm
