// The flux-map reader's rules as data, for the Python side (scenarios/maps/rules.py): the
// metadata table and its rule's constants, the reader's limits and the operating region's
// constants, written by the build (fmu_src/CMakeLists.txt) so that Python states none of them
// again and parses no C++. The repository carries the generated file (map_rules.json beside
// this source; tests/python/test_map_rules.py keeps it equal to the build's).
#include <charconv>
#include <cstdio>
#include <fstream>
#include <string>

#include "machine/flux_map.hpp"
#include "machine/flux_map_metadata.hpp"
#include "machine/map_file.hpp"
#include "machine/operating_region.hpp"

namespace {

// The shortest text that reads back as x.
std::string number(double x) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, x);
    return std::string(buf, r.ptr);
}

std::string quoted(const std::string& s) { return "\"" + s + "\""; }  // table names: no escapes needed

}  // namespace

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: write_map_rules OUT.json\n");
        return 2;
    }
    using namespace ipmsm;
    std::string json = "{\n  \"metadata\": [\n";
    const auto& keys = metadata_keys();
    for (std::size_t i = 0; i < keys.size(); ++i) {
        const MetadataKey& k = keys[i];
        json += "    {\"key\": " + quoted(k.key) + ", \"unit\": " + quoted(k.unit) +
                ", \"parameter\": " + quoted(k.parameter) + ", \"checked\": " + (k.checked ? "true" : "false") +
                ", \"whole_number\": " + (k.whole_number ? "true" : "false") + "}" +
                (i + 1 < keys.size() ? ",\n" : "\n");
    }
    json += "  ],\n  \"coldest_kelvin\": " + number(kColdestKelvin) + ",\n";
    json += "  \"map_limits\": {\"max_bytes\": " + std::to_string(kMaxMapFileBytes) +
            ", \"max_line_chars\": " + std::to_string(kMaxLineChars) +
            ", \"max_axis\": " + std::to_string(kMaxGridAxis) + ", \"max_points\": " + std::to_string(kMaxGridPoints) +
            "},\n";
    json += "  \"operating_region\": {\"margin\": " + number(kOperatingMargin) +
            ", \"magnet_fraction\": " + number(kMagnetFraction) + ", \"fold_relative\": " + number(kFoldRelative) +
            "}\n}\n";
    std::ofstream out(argv[1], std::ios::binary);
    out << json;
    return out ? 0 : 1;
}
