// The flux map's '# key: value' metadata against the FMUs' parameters: one rule and one set of
// messages for both FMUs. The parameters rule; the metadata only give warnings.
#pragma once

#include <string>
#include <vector>

#include "machine/flux_map.hpp"

namespace ipmsm {

// A parameter and the metadata key that describes it, e.g. {"R_s_ohm", "R_s", 0.012}.
struct MetadataCheck {
    const char* key;
    const char* parameter;
    double value;  // the parameter's value, in the contract's SI unit
};

// The contract's SI unit of a metadata key ("Ohm" for R_s_ohm, "" for pole_pairs and unknown keys).
const char* metadata_unit(const std::string& key);

// One warning per check whose key is in the map's metadata and whose value
// - does not start with a number ("# pole_pairs: four"),
// - is followed by a unit other than the key's SI unit ("# R_s_ohm: 12 mOhm"; words after a
//   unitless key's number, or in parentheses, are a comment: "# pole_pairs: 4 (8 poles)"), or
// - differs from the parameter by more than 1e-9 relative.
std::vector<std::string> metadata_warnings(const FluxMapTable& table, const std::string& map_name,
                                           const std::vector<MetadataCheck>& checks);

}  // namespace ipmsm
