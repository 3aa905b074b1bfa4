// Metadata against parameters; see flux_map_metadata.hpp.
#include "machine/flux_map_metadata.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <sstream>

#include "machine/map_file.hpp"

namespace ipmsm {
namespace {

bool same_unit(const std::string& a, const std::string& b) {
    return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
               return std::tolower(static_cast<unsigned char>(x)) == std::tolower(static_cast<unsigned char>(y));
           });
}

std::string trim(const std::string& s) {
    const auto b = s.find_first_not_of(" \t");
    return b == std::string::npos ? std::string() : s.substr(b, s.find_last_not_of(" \t") - b + 1);
}

std::string num(double x) {
    std::ostringstream os;
    os.precision(10);
    os << x;
    return os.str();
}

}  // namespace

const std::vector<MetadataKey>& metadata_keys() {
    static const std::vector<MetadataKey> keys = {
        {"pole_pairs", "", "pole_pairs", true, true},
        {"R_s_ohm", "Ohm", "R_s", true},
        {"T_winding_ref_K", "K", "T_winding_ref", true},
        {"alpha_cu_per_K", "1/K", "alpha_cu", true},
        {"T_magnet_ref_K", "K", "T_magnet_ref", true},
        {"k_psi_T_per_K", "1/K", "k_psi_T", true},
        {"fe_k_h_W_per_Hz", "W/Hz", "fe_k_h", true},
        {"fe_alpha", "", "fe_alpha", true},
        {"fe_k_e_W_per_Hz2", "W/Hz^2", "fe_k_e", true},
        {"fe_psi_ref_Wb", "Wb", "fe_psi_ref", true},
        {"I_max_A", "A", "I_max", false},
        {"u_dc_V", "V", "lut_u_dc", false},
        {"k_u", "", "k_u", false},
        {"w_m_max_rad_s", "rad/s", "w_m_max", false},
    };
    return keys;
}

const char* metadata_unit(const std::string& key) {
    for (const MetadataKey& k : metadata_keys())
        if (key == k.key) return k.unit;
    return "";
}

double metadata_value(const MetadataKey& k, const std::string& text) {
    const std::string unit = k.unit;
    const MetadataValue m = split_metadata_value(text);
    // what the value is, never the file's text (a map parameter may name any file: map_file.hpp)
    const std::string shown = m.is_number
                                  ? num(m.value) + (m.rest.empty() ? "" : " then " + unit_or_description(m.rest))
                                  : describe_token(text);
    auto refuse = [&](const std::string& why) -> double {
        throw FluxMapError(std::string("metadata ") + k.key + ": " + shown + ": " + why +
                           " (docs/maps.md, \"Metadata\")");
    };
    if (!m.is_number)
        return refuse("expected a finite number" + (unit.empty() ? std::string() : " in " + unit) +
                      ", optionally followed by a comment in parentheses");
    std::string rest = m.rest;
    if (!unit.empty() && rest.size() >= unit.size() && same_unit(rest.substr(0, unit.size()), unit) &&
        (rest.size() == unit.size() || rest[unit.size()] == ' ' || rest[unit.size()] == '\t' ||
         rest[unit.size()] == '('))
        rest = trim(rest.substr(unit.size()));
    if (!rest.empty() && !(rest.front() == '(' && rest.back() == ')'))
        return refuse("a number" + (unit.empty() ? std::string(" without a unit") : " in " + unit) +
                      ", optionally followed by a comment in parentheses; " + unit_or_description(rest) +
                      " is neither" + (unit.empty() ? "" : " (another unit is not converted)"));
    if (k.whole_number && m.value != std::floor(m.value)) return refuse("expected a whole number");
    if (unit == "K" && m.value < kColdestKelvin)
        return refuse("expected a temperature in K of at least " + num(kColdestKelvin) + " K (" + num(m.value) +
                      " K can only be meant in degC)");
    return m.value;
}

void check_metadata(const std::map<std::string, std::string>& metadata, const std::string& map_name) {
    for (const MetadataKey& k : metadata_keys()) {
        const auto it = metadata.find(k.key);
        if (it == metadata.end()) continue;
        try {
            metadata_value(k, it->second);
        } catch (const FluxMapError& e) {
            throw FluxMapError("flux map '" + quoted_excerpt(map_name) + "': " + e.what());
        }
    }
}

std::vector<std::string> metadata_warnings(const FluxMapTable& table, const std::string& map_name,
                                           const ParameterValue& parameter) {
    std::vector<std::string> out;
    for (const MetadataKey& k : metadata_keys()) {
        if (!k.checked) continue;
        const auto it = table.metadata.find(k.key);
        if (it == table.metadata.end()) continue;
        const std::optional<double> value = parameter(k.parameter);
        if (!value) continue;
        // (the value as read, never the file's text: describe_token, map_file.hpp)
        const double stated = metadata_value(k, it->second);
        const std::string unit = k.unit;
        const std::string said = "flux map " + quoted_excerpt(map_name) + " says " + k.key + ": " + num(stated) +
                                 (unit.empty() ? "" : " " + unit);
        if (std::abs(stated - *value) > 1e-9 * std::max(std::abs(stated), std::abs(*value)))
            out.push_back(said + ", but the parameter " + k.parameter + " is " + num(*value) +
                          (unit.empty() ? "" : " " + unit) + "; using the parameter");
    }
    return out;
}

}  // namespace ipmsm
