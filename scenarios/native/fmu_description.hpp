// The GUID and value references of an unzipped FMU's modelDescription.xml, read with a plain
// attribute search (enough for the generated files of this project). For the C++ drivers of
// libipmsm_cosim (cosim_check, cosim_profile).
#pragma once

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

namespace cosim_tools {

struct Description {
    std::string guid;
    std::map<std::string, unsigned> vr;
};

inline std::string attribute_after(const std::string& xml, std::size_t from, const char* attr) {
    const std::string key = std::string(" ") + attr + "=\"";
    const std::size_t a = xml.find(key, from);
    if (a == std::string::npos) return "";
    const std::size_t b = xml.find('"', a + key.size());
    return xml.substr(a + key.size(), b - a - key.size());
}

inline Description read_description(const std::string& dir) {
    std::ifstream f(dir + "/modelDescription.xml");
    std::stringstream ss;
    ss << f.rdbuf();
    const std::string xml = ss.str();
    Description d;
    d.guid = attribute_after(xml, 0, "guid");
    for (std::size_t p = xml.find("<ScalarVariable"); p != std::string::npos; p = xml.find("<ScalarVariable", p + 1))
        d.vr[attribute_after(xml, p, "name")] = static_cast<unsigned>(std::stoul(attribute_after(xml, p, "valueReference")));
    if (d.guid.empty() || d.vr.empty()) {
        std::fprintf(stderr, "cannot read %s/modelDescription.xml\n", dir.c_str());
        std::exit(2);
    }
    return d;
}

}  // namespace cosim_tools
