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

struct KeyUnit {
    const char* key;
    const char* unit;
};
// The contract's metadata keys (INTERFACE.md, the map format) and their SI units.
constexpr KeyUnit kKeyUnits[] = {
    {"pole_pairs", ""},          {"R_s_ohm", "Ohm"},      {"T_winding_ref_K", "K"},
    {"alpha_cu_per_K", "1/K"},   {"T_magnet_ref_K", "K"}, {"k_psi_T_per_K", "1/K"},
    {"fe_k_h_W_per_Hz", "W/Hz"}, {"fe_alpha", ""},        {"fe_k_e_W_per_Hz2", "W/Hz^2"},
    {"fe_psi_ref_Wb", "Wb"},     {"I_max_A", "A"},        {"u_dc_V", "V"},
};

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

const char* metadata_unit(const std::string& key) {
    for (const KeyUnit& k : kKeyUnits)
        if (key == k.key) return k.unit;
    return "";
}

std::vector<std::string> metadata_warnings(const FluxMapTable& table, const std::string& map_name,
                                           const std::vector<MetadataCheck>& checks) {
    std::vector<std::string> out;
    for (const MetadataCheck& c : checks) {
        const auto it = table.metadata.find(c.key);
        if (it == table.metadata.end()) continue;
        const std::string said =
            "flux map " + quoted_excerpt(map_name) + " says " + c.key + ": " + quoted_excerpt(it->second);
        const MetadataValue m = split_metadata_value(it->second);
        if (!m.is_number) {
            out.push_back(said + ", which does not start with a number: ignored (the parameter " + c.parameter +
                          " is " + num(c.value) + ")");
            continue;
        }
        const std::string unit = metadata_unit(c.key);
        const std::string word = m.rest.substr(0, m.rest.find_first_of(" \t("));
        if (!unit.empty() && !word.empty() && !same_unit(word, unit)) {
            out.push_back(said + ": the unit '" + quoted_excerpt(word, 40) + "' is not the contract's SI unit " + unit +
                          "; the value is ignored (the parameter " + c.parameter + " is " + num(c.value) + " " + unit +
                          ")");
            continue;
        }
        if (std::abs(m.value - c.value) > 1e-9 * std::max(std::abs(m.value), std::abs(c.value)))
            out.push_back(said + ", but the parameter " + c.parameter + " is " + num(c.value) +
                          (unit.empty() ? "" : " " + unit) + "; using the parameter");
    }
    return out;
}

}  // namespace ipmsm
