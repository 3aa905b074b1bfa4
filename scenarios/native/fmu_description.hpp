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

#include "cosim.h"

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

// ipmsm_cosim_couple with the value references it takes (cosim.h), by name: controller unit 0,
// plant unit 1.
inline int couple(ipmsm_cosim* m, const Description& cd, const Description& pd, long long k0 = 0) {
    const unsigned cvr[8] = {cd.vr.at("T_ref"), cd.vr.at("w_m"), cd.vr.at("u_dc"), cd.vr.at("T_magnet"),
                             cd.vr.at("i_d"), cd.vr.at("i_q"), cd.vr.at("u_d_ref"), cd.vr.at("u_q_ref")};
    const unsigned pvr[7] = {pd.vr.at("u_d"), pd.vr.at("u_q"), pd.vr.at("w_m"), pd.vr.at("T_magnet"),
                             pd.vr.at("T_winding"), pd.vr.at("i_d"), pd.vr.at("i_q")};
    return ipmsm_cosim_couple(m, cvr, pvr, k0);
}

}  // namespace cosim_tools
