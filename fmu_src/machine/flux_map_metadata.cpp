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

std::string num(double x) {
    std::ostringstream os;
    os.precision(10);
    os << x;
    return os.str();
}

}  // namespace

const std::vector<MetadataKey>& metadata_keys() {
    static const std::vector<MetadataKey> keys = {
        {"pole_pairs", "", "pole_pairs", true},
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
    };
    return keys;
}

const char* metadata_unit(const std::string& key) {
    for (const MetadataKey& k : metadata_keys())
        if (key == k.key) return k.unit;
    return "";
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
        const MetadataValue m = split_metadata_value(it->second);
        const std::string said = "flux map " + quoted_excerpt(map_name) + " says " + k.key;
        if (!m.is_number) {
            out.push_back(said + " with a value that does not start with a number (" + describe_token(it->second) +
                          "): ignored (the parameter " + k.parameter + " is " + num(*value) + ")");
            continue;
        }
        const std::string unit = k.unit;
        const std::string word = m.rest.substr(0, m.rest.find_first_of(" \t("));
        if (!unit.empty() && !word.empty() && !same_unit(word, unit)) {
            out.push_back(said + ": " + num(m.value) + ", but the unit " + unit_or_description(word) +
                          " is not the contract's SI unit " + unit + "; the value is ignored (the parameter " +
                          k.parameter + " is " + num(*value) + " " + unit + ")");
            continue;
        }
        if (std::abs(m.value - *value) > 1e-9 * std::max(std::abs(m.value), std::abs(*value)))
            out.push_back(said + ": " + num(m.value) + (unit.empty() ? "" : " " + unit) + ", but the parameter " +
                          k.parameter + " is " + num(*value) + (unit.empty() ? "" : " " + unit) +
                          "; using the parameter");
    }
    return out;
}

}  // namespace ipmsm
