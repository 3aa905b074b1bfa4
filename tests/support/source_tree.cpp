#include "source_tree.hpp"

namespace ipmsm {

const std::string& source_dir() {
    static const std::string dir = IPMSM_SOURCE_DIR;
    return dir;
}

std::string source_path(const std::string& relative) { return source_dir() + "/" + relative; }

}  // namespace ipmsm
