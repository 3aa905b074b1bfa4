// The flux map's '# key: value' metadata against the FMUs' parameters: one table of which key
// describes which parameter, one rule and one set of messages for every FMU. The parameters
// rule; the metadata only give warnings.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "machine/flux_map.hpp"

namespace ipmsm {

// A metadata key of the contract (INTERFACE.md, the map format), its SI unit and the FMU
// parameter it describes. checked: the map describes the motor, so a parameter that differs is
// worth a warning; otherwise the key is only the parameter's default (a caller may choose a lower
// current limit, or tables for another DC voltage, on purpose).
struct MetadataKey {
    const char* key;
    const char* unit;  // "" for a number without unit
    const char* parameter;
    bool checked;
};

// The table, in the order the warnings come in: the one C++ statement of the mapping.
const std::vector<MetadataKey>& metadata_keys();

// The contract's SI unit of a metadata key ("Ohm" for R_s_ohm, "" for pole_pairs and unknown keys).
const char* metadata_unit(const std::string& key);

// The value of a model's parameter by name, in the contract's SI unit; nullopt if it has none.
using ParameterValue = std::function<std::optional<double>(const std::string& parameter)>;

// One warning per checked key whose parameter the model has and that is in the map's metadata,
// when its value
// - does not start with a number ("# pole_pairs: four"),
// - is followed by a unit other than the key's SI unit ("# R_s_ohm: 12 mOhm"; words after a
//   unitless key's number, or in parentheses, are a comment: "# pole_pairs: 4 (8 poles)"), or
// - differs from the parameter by more than 1e-9 relative.
std::vector<std::string> metadata_warnings(const FluxMapTable& table, const std::string& map_name,
                                           const ParameterValue& parameter);

}  // namespace ipmsm
