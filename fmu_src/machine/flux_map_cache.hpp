// Parsed flux maps shared by content: a map read again (fmi2ExitInitializationMode after a
// preview in Initialization Mode, every Set-then-Get there, a second instance) is parsed and
// splined once. The file's bytes are read each time (bounded, map_file.hpp), so an edited file
// is a new map: the cache is keyed on the content (64-bit FNV-1a and length), not on the path.
#pragma once

#include <memory>
#include <string>

#include "machine/flux_map.hpp"

namespace ipmsm {

// The map in the file at path (read_flux_map's errors); thread-safe. The last few maps are kept.
std::shared_ptr<const FluxMap> shared_flux_map(const std::string& path);
// The map in `text` (the contract's format), parsed as the file `name` would be; the same cache.
std::shared_ptr<const FluxMap> shared_flux_map_text(const std::string& text, const std::string& name);

}  // namespace ipmsm
