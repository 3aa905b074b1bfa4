// The flux map's '# key: value' metadata against the FMUs' parameters: one table of which key
// describes which parameter, one rule and one set of messages for every FMU. The parameters
// rule; the metadata only give warnings.
#pragma once

#include <functional>
#include <map>
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
    bool whole_number = false;  // a count (pole_pairs): 7.99 is refused, never truncated
};

// The table, in the order the warnings come in: the one statement of the mapping, for both
// languages (the build writes it for the Python side: write_map_rules.cpp).
const std::vector<MetadataKey>& metadata_keys();

// A temperature a key states in K is at least this: a value below it can only be meant in degC
// (-73 degC; no traction machine is rated below -40 degC, IEC 60068-2-1's coldest test).
inline constexpr double kColdestKelvin = 200.0;

// A contract key's value by the one rule (docs/maps.md, "Metadata"; the Python reader applies the
// same): a finite number, then optionally the key's SI unit (case aside), then optionally a
// comment in parentheses, and nothing else; a whole number for a count; at least kColdestKelvin
// for a temperature in K. "12 mOhm", "12000 rpm", "4 poles" and "7.99" (pole_pairs) are refused:
// FluxMapError naming the key.
double metadata_value(const MetadataKey& key, const std::string& text);

// Every contract key the map states, read by that rule: FluxMapError naming the first that
// breaks it (map_name: for the message).
void check_metadata(const std::map<std::string, std::string>& metadata, const std::string& map_name);

// The contract's SI unit of a metadata key ("Ohm" for R_s_ohm, "" for pole_pairs and unknown keys).
const char* metadata_unit(const std::string& key);

// The value of a model's parameter by name, in the contract's SI unit; nullopt if it has none.
using ParameterValue = std::function<std::optional<double>(const std::string& parameter)>;

// One warning per checked key whose parameter the model has and that is in the map's metadata,
// when its value (read by metadata_value: a value it refuses is an error, as the reader's)
// differs from the parameter by more than 1e-9 relative.
std::vector<std::string> metadata_warnings(const FluxMapTable& table, const std::string& map_name,
                                           const ParameterValue& parameter);

}  // namespace ipmsm
