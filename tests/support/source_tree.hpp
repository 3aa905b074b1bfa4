// Files of the source tree the tests and benchmarks read (the shipped map, the real maps, test
// data): source_path("fmu_src/resources") is "<the clone's root>/fmu_src/resources".
#pragma once

#include <string>

namespace ipmsm {

// The source tree's root, compiled into source_tree.cpp only: every other object is the same in
// any clone, so that a fresh clone compiles it from the compiler cache (scripts/compiler_cache.sh).
const std::string& source_dir();

// A path inside the source tree, given relative to its root.
std::string source_path(const std::string& relative);

}  // namespace ipmsm
