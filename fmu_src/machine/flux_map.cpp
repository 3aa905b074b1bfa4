// Flux maps: the contract's CSV reader, the linear machine's map, and the spline interpolant.
#include "machine/flux_map.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <istream>
#include <sstream>
#include <system_error>

#include "machine/flux_map_metadata.hpp"
#include "machine/machine.hpp"
#include "machine/map_file.hpp"

namespace ipmsm {
namespace {

const char* const kColumns[4] = {"i_d", "i_q", "psi_d", "psi_q"};

std::string trim(const std::string& s) {
    const char* ws = " \t\r\n\f\v";
    const auto b = s.find_first_not_of(ws);
    if (b == std::string::npos) return std::string();
    const auto e = s.find_last_not_of(ws);
    return s.substr(b, e - b + 1);
}

std::vector<std::string> split_commas(const std::string& s) {
    std::vector<std::string> out;
    std::size_t start = 0;
    for (;;) {
        const auto c = s.find(',', start);
        out.push_back(trim(s.substr(start, c == std::string::npos ? std::string::npos : c - start)));
        if (c == std::string::npos) break;
        start = c + 1;
    }
    return out;
}

// What a header line holds, without its content: "2 fields", or the first field that is not the
// expected column's name ("4 fields; field 1 is a word of 2 characters, not 'i_d'").
std::string fields_found(const std::vector<std::string>& f, const char* const (&columns)[4]) {
    std::string out = std::to_string(f.size()) + (f.size() == 1 ? " field" : " fields");
    for (std::size_t c = 0; c < f.size() && c < 4; ++c)
        if (f[c] != columns[c])
            return out + "; field " + std::to_string(c + 1) + " is " + describe_token(f[c]) + ", not '" + columns[c] +
                   "'";
    return out;
}

std::string fmt(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.9g", v);
    return b;
}

enum class NumStatus { ok, not_a_number, non_finite };

// The whole (trimmed) text must be one number. std::from_chars rather than strtod: the same
// strictness with an end-pointer check, but independent of the C locale, which the simulation
// tool hosting the FMU may have set to a decimal comma.
NumStatus parse_number(const std::string& text, double& value) {
    const char* b = text.data();
    const char* e = b + text.size();
    if (b != e && *b == '+' && e - b > 1 && *(b + 1) != '-' && *(b + 1) != '+') ++b;
    if (b == e) return NumStatus::not_a_number;
    const auto r = std::from_chars(b, e, value, std::chars_format::general);
    if (r.ptr != e) return NumStatus::not_a_number;
    if (r.ec == std::errc::result_out_of_range) {
        // Overflow is non-finite; underflow (e.g. 1e-400) is a legitimate zero.
        double mag = 0;
        for (const char* p = b; p < e; ++p)
            if (*p == 'e' || *p == 'E') {
                mag = std::atof(p + 1);  // only the exponent's sign matters; text already checked
                break;
            }
        if (mag < 0) {
            value = 0.0;
            return NumStatus::ok;
        }
        return NumStatus::non_finite;
    }
    if (r.ec != std::errc()) return NumStatus::not_a_number;
    return std::isfinite(value) ? NumStatus::ok : NumStatus::non_finite;
}

bool is_metadata_key(const std::string& k) {
    if (k.empty() || !(std::isalpha(static_cast<unsigned char>(k[0])) || k[0] == '_')) return false;
    for (char c : k)
        if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '-')) return false;
    return true;
}

struct Row {
    double v[4];
    int line;
};

// Sorted distinct values; values within tol of the previous distinct value are the same node
// (guards against 1e-15-level noise from spreadsheets and FEM exports).
std::vector<double> distinct_axis(std::vector<double> v, double& tol) {
    std::sort(v.begin(), v.end());
    tol = 1e-9 * std::max(v.back() - v.front(), 1e-300);
    std::vector<double> out;
    for (double x : v)
        if (out.empty() || x - out.back() > tol) out.push_back(x);
    return out;
}

int axis_index(const std::vector<double>& axis, double x, double tol) {
    auto it = std::lower_bound(axis.begin(), axis.end(), x - tol);
    return static_cast<int>(it - axis.begin());
}

// ", missing e.g. (i_d = .. A, i_q = .. A)" for a grid that lacks points (rows < nd nq), found
// without allocating the grid: the first axis pair, in order, that no row has.
std::string missing_point(const std::vector<Row>& rows, const std::vector<double>& i_d, const std::vector<double>& i_q,
                          double tol_d, double tol_q) {
    if (rows.size() >= i_d.size() * i_q.size()) return "";
    std::vector<std::pair<int, int>> have;
    have.reserve(rows.size());
    for (const Row& r : rows) have.emplace_back(axis_index(i_q, r.v[1], tol_q), axis_index(i_d, r.v[0], tol_d));
    std::sort(have.begin(), have.end());
    have.erase(std::unique(have.begin(), have.end()), have.end());
    std::size_t n = 0;
    for (int k = 0; k < static_cast<int>(i_q.size()); ++k)
        for (int j = 0; j < static_cast<int>(i_d.size()); ++j, ++n)
            if (n >= have.size() || have[n] != std::make_pair(k, j))
                return "; missing e.g. (i_d = " + fmt(i_d[j]) + " A, i_q = " + fmt(i_q[k]) + " A)";
    return "";
}

}  // namespace

double FluxMapTable::metadata_number(const std::string& key, double fallback) const {
    const auto it = metadata.find(key);
    if (it == metadata.end()) return fallback;
    const MetadataValue m = split_metadata_value(it->second);
    if (!m.is_number)
        throw FluxMapError("flux-map metadata '" + key + "': the value (" + describe_token(it->second) +
                           ") does not start with a finite number");
    return m.value;
}

MetadataValue split_metadata_value(const std::string& text) {
    // The longest prefix that is a number, then the rest: "4 (8 poles)" is 4 and "(8 poles)".
    MetadataValue m;
    const std::string s = trim(text);
    // no number is longer than 64 characters: the scan stays short whatever the value's length
    const std::size_t end = std::min<std::size_t>(s.find_first_of(" \t("), std::min<std::size_t>(s.size(), 64));
    for (std::size_t n = end; n > 0; --n)
        if (parse_number(s.substr(0, n), m.value) == NumStatus::ok) {
            m.is_number = true;
            m.rest = trim(s.substr(n));
            return m;
        }
    m.rest = s;
    return m;
}

namespace {

// The lines of a text: LF, CRLF and CR (old Mac exports) all end one.
class Lines {
public:
    explicit Lines(const std::string& text) : s_(text) {}
    // The next line, or false at the end; a line longer than kMaxLineChars is not copied:
    // `length` says how long it is and `line` is its first kMaxLineChars characters.
    bool next(std::string& line, std::size_t& length) {
        if (pos_ >= s_.size()) return false;
        const std::size_t e = s_.find_first_of("\r\n", pos_);
        const std::size_t end = e == std::string::npos ? s_.size() : e;
        length = end - pos_;
        line.assign(s_, pos_, std::min(length, kMaxLineChars));
        pos_ = end;
        if (pos_ < s_.size() && s_[pos_] == '\r') {
            ++pos_;
            if (pos_ < s_.size() && s_[pos_] == '\n') ++pos_;
        } else if (pos_ < s_.size()) {
            ++pos_;
        }
        return true;
    }

private:
    const std::string& s_;
    std::size_t pos_ = 0;
};

}  // namespace

FluxMapTable parse_flux_map(std::istream& in, const std::string& source_name) {
    std::string text;
    char buf[65536];
    while (in.read(buf, sizeof buf) || in.gcount() > 0) {
        if (text.size() + static_cast<std::size_t>(in.gcount()) > kMaxMapFileBytes)
            throw FluxMapError("flux map '" + quoted_excerpt(source_name) + "': larger than " +
                               std::to_string(kMaxMapFileBytes) + " bytes, the limit for a flux map");
        text.append(buf, static_cast<std::size_t>(in.gcount()));
    }
    if (in.bad()) throw FluxMapError("flux map '" + quoted_excerpt(source_name) + "': read error");
    return parse_flux_map_text(text, source_name);
}

FluxMapTable parse_flux_map_text(const std::string& text, const std::string& source_name) {
    const std::string where = "flux map '" + quoted_excerpt(source_name) + "'";
    auto fail_line = [&](int line, const std::string& what) {
        throw FluxMapError(where + ", line " + std::to_string(line) + ": " + what);
    };
    auto fail = [&](const std::string& what) { throw FluxMapError(where + ": " + what); };

    FluxMapTable t;
    t.content_hash = content_hash(text);
    std::vector<Row> rows;
    std::string raw;
    std::size_t length = 0;
    int line = 0, header_line = 0, content_lines = 0;
    Lines lines(text);
    while (lines.next(raw, length)) {
        ++line;
        if (length > kMaxLineChars)
            fail_line(line, "line of " + std::to_string(length) + " characters; the limit is " +
                                std::to_string(kMaxLineChars));
        if (line == 1 && raw.size() >= 3 && raw.compare(0, 3, "\xEF\xBB\xBF") == 0)
            raw.erase(0, 3);  // UTF-8 byte-order mark (spreadsheet exports)
        if (line == 1 && raw.size() >= 2 && (raw.compare(0, 2, "\xFF\xFE") == 0 || raw.compare(0, 2, "\xFE\xFF") == 0))
            fail_line(line, "the file is UTF-16 (byte-order mark FF FE or FE FF): save it as UTF-8 or ASCII");
        const std::string s = trim(raw);
        if (s.empty()) continue;
        ++content_lines;
        if (s[0] == '#') {
            const std::string body = trim(s.substr(1));
            const auto colon = body.find(':');
            if (colon != std::string::npos) {
                const std::string key = trim(body.substr(0, colon));
                if (is_metadata_key(key)) t.metadata[key] = trim(body.substr(colon + 1));
            }
            continue;
        }
        if (header_line == 0) {
            const auto f = split_commas(s);
            bool ok = f.size() == 4;
            for (int c = 0; ok && c < 4; ++c) ok = f[c] == kColumns[c];
            if (!ok) {
                double dummy;
                const bool numeric = !f.empty() && parse_number(f[0], dummy) == NumStatus::ok;
                fail_line(line, std::string(numeric ? "header missing" : "wrong header") +
                                    ": expected 'i_d,i_q,psi_d,psi_q', found " + fields_found(f, kColumns));
            }
            header_line = line;
            continue;
        }
        const auto f = split_commas(s);
        if (f.size() != 4)
            fail_line(line,
                      "expected 4 comma-separated values (i_d,i_q,psi_d,psi_q), found " + std::to_string(f.size()));
        if (rows.size() == kMaxGridPoints)
            fail_line(line, "more than " + std::to_string(kMaxGridPoints) + " data rows, the limit for a flux map (" +
                                std::to_string(kMaxGridAxis) + " x " + std::to_string(kMaxGridAxis) + ")");
        Row r;
        r.line = line;
        for (int c = 0; c < 4; ++c) {
            switch (parse_number(f[c], r.v[c])) {
                case NumStatus::ok: break;
                case NumStatus::not_a_number:
                    fail_line(line,
                              std::string("column ") + kColumns[c] + ": " + describe_token(f[c]) + " is not a number");
                    break;
                case NumStatus::non_finite:
                    fail_line(line, std::string("column ") + kColumns[c] +
                                        ": a non-finite value (infinite, not a number, or beyond a double's range)");
                    break;
            }
        }
        rows.push_back(r);
    }
    if (content_lines == 0) fail("empty file (expected '#' lines, the header 'i_d,i_q,psi_d,psi_q' and data rows)");
    if (header_line == 0)
        fail("no header line 'i_d,i_q,psi_d,psi_q' and no data (only '#' lines, " + std::to_string(line) + " lines)");
    if (rows.empty())
        fail_line(header_line, "header but no data rows (file ends at line " + std::to_string(line) + ")");

    // The grid: distinct axis values, every (i_d, i_q) pair exactly once.
    std::vector<double> vd, vq;
    vd.reserve(rows.size());
    vq.reserve(rows.size());
    for (const Row& r : rows) {
        vd.push_back(r.v[0]);
        vq.push_back(r.v[1]);
    }
    double tol_d, tol_q;
    t.i_d = distinct_axis(vd, tol_d);
    t.i_q = distinct_axis(vq, tol_q);
    const std::size_t nd = t.i_d.size(), nq = t.i_q.size();
    // Before the grid is allocated: rows with distinct currents would ask for rows^2 points. More
    // rows than points (nd nq < rows) means a duplicate, which the loop below names.
    if (nd > kMaxGridAxis || nq > kMaxGridAxis || nd * nq > rows.size())
        fail("grid is not full and rectangular: " + std::to_string(nd) + " distinct i_d x " + std::to_string(nq) +
             " distinct i_q values need " + std::to_string(nd * nq) + " rows, found " + std::to_string(rows.size()) +
             (nd > kMaxGridAxis || nq > kMaxGridAxis
                  ? " (and more than " + std::to_string(kMaxGridAxis) + " values on an axis, the limit)"
                  : missing_point(rows, t.i_d, t.i_q, tol_d, tol_q)));
    std::vector<int> at(nd * nq, 0);  // line of each grid point, 0: none yet
    t.psi_d.assign(nd * nq, 0.0);
    t.psi_q.assign(nd * nq, 0.0);
    for (const Row& r : rows) {
        const std::size_t j = axis_index(t.i_d, r.v[0], tol_d), k = axis_index(t.i_q, r.v[1], tol_q);
        const std::size_t idx = k * nd + j;
        if (at[idx] != 0)
            fail_line(r.line, "duplicate grid point (i_d = " + fmt(r.v[0]) + " A, i_q = " + fmt(r.v[1]) +
                                  " A), first given on line " + std::to_string(at[idx]));
        at[idx] = r.line;
        t.psi_d[idx] = r.v[2];
        t.psi_q[idx] = r.v[3];
    }
    if (nd < 4 || nq < 4)
        fail("grid has " + std::to_string(nd) + " i_d x " + std::to_string(nq) +
             " i_q points; at least 4 x 4 are needed");

    // Monotonicity is not the reader's to judge: where a map must be legal depends on the drive
    // (operating_region.hpp, the FMUs' initialisation). The metadata's values are (one rule).
    check_metadata(t.metadata, source_name);
    return t;
}

FluxMapTable read_flux_map(const std::string& path) {
    std::string text;
    try {
        text = read_map_file(path);
    } catch (const MapFileError& e) {
        throw FluxMapError("flux map '" + quoted_excerpt(path) + "': " + e.what());
    }
    return parse_flux_map_text(text, path);
}

std::uint64_t content_hash(const std::string& bytes) {
    std::uint64_t h = 0xcbf29ce484222325ull;  // 64-bit FNV-1a
    for (const char c : bytes) {
        h ^= static_cast<unsigned char>(c);
        h *= 0x100000001b3ull;
    }
    return h;
}

void check_map_content(MapContent saved, const FluxMap* map) {
    const MapContent here = map_content(map);
    if (saved == MapContent{0} || saved == here) return;
    char text[160];
    std::snprintf(text, sizeof text,
                  "the FMU state was saved on a flux map with content hash %016llx; the map loaded "
                  "here has %016llx",
                  static_cast<unsigned long long>(saved), static_cast<unsigned long long>(here));
    throw FluxMapError(std::string(text) + " (the file changed since, or flux_map names another file): not restored");
}

MapSpan map_span(const FluxMapTable& t) {
    auto range = [](const std::vector<double>& v, double out[2]) {
        const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
        out[0] = v.empty() ? 0.0 : *lo;
        out[1] = v.empty() ? 0.0 : *hi;
    };
    MapSpan s{};
    range(t.i_d, s.i_d);
    range(t.i_q, s.i_q);
    range(t.psi_d, s.psi_d);
    range(t.psi_q, s.psi_q);
    for (std::size_t n = 0; n < t.psi_d.size() && n < t.psi_q.size(); ++n)
        s.psi_abs_max = std::max(s.psi_abs_max, std::hypot(t.psi_d[n], t.psi_q[n]));
    return s;
}

double flux_reach(const MapSpan& span, double psi_m, double k_psi_T) {
    return kSplineReach * span.psi_abs_max + std::abs(k_psi_T * psi_m) * (kTemperatureMax_K - kTemperatureMin_K);
}

FluxMap::FluxMap(const FluxMapTable& table) : table_(table) {
    const std::size_t N = table.i_d.size() * table.i_q.size();
    if (table.psi_d.size() != N || table.psi_q.size() != N)
        throw FluxMapError("FluxMap: table has " + std::to_string(table.i_d.size()) + " x " +
                           std::to_string(table.i_q.size()) + " grid but " + std::to_string(table.psi_d.size()) +
                           " psi_d and " + std::to_string(table.psi_q.size()) + " psi_q values");
    try {
        spline_ = BicubicSpline2D(table.i_d, table.i_q, {table.psi_d.data(), table.psi_q.data()});
    } catch (const std::invalid_argument& e) {
        throw FluxMapError(std::string("FluxMap: ") + e.what());
    }
    psi_m_ = eval(0.0, 0.0).psi_d;
}

}  // namespace ipmsm
