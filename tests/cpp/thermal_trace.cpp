// The machine's thermal network stepped over a CSV of steps on stdin, for the Python tests that
// check it against scipy (tests/python/test_thermal_network.py).
//
//   thermal_trace THETA0_K [NAME=VALUE ...]   (NAME: a scalar of thermal::LptnParams)
//   stdin, one step a line: h_s,E_cu_J,E_fe_J,w_m_rad_s,I_rms_A,T_coolant_K,T_ambient_K
//   stdout, one line a step: theta_stator_yoke,theta_stator_tooth,theta_winding,theta_magnet (K),
//                            E_loss,E_stored,E_coolant,E_ambient (J)
// Exit 2 with a message on bad input.
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <map>
#include <string>

#include "thermal/motor_thermal.hpp"

using namespace ipmsm::thermal;

int main(int argc, char** argv) {
    try {
        if (argc < 2) throw std::invalid_argument("usage: thermal_trace THETA0_K [NAME=VALUE ...]");
        LptnParams p;
        const std::map<std::string, double*> scalars = {{"C_stator_yoke", &p.C_stator_yoke},
                                                        {"C_stator_tooth", &p.C_stator_tooth},
                                                        {"C_winding", &p.C_winding},
                                                        {"C_magnet", &p.C_magnet},
                                                        {"R_yoke_winding", &p.R_yoke_winding},
                                                        {"R_yoke_tooth", &p.R_yoke_tooth},
                                                        {"R_tooth_winding", &p.R_tooth_winding},
                                                        {"R_coolant_yoke", &p.R_coolant_yoke},
                                                        {"k_coolant_yoke", &p.k_coolant_yoke},
                                                        {"k_fe_yoke", &p.k_fe_yoke},
                                                        {"w_m_ref", &p.w_m_ref},
                                                        {"I_rms_ref", &p.I_rms_ref}};
        for (int a = 2; a < argc; ++a) {
            const std::string arg = argv[a];
            const auto eq = arg.find('=');
            const auto it = scalars.find(arg.substr(0, eq));
            if (eq == std::string::npos || it == scalars.end()) throw std::invalid_argument("unknown parameter " + arg);
            *it->second = std::stod(arg.substr(eq + 1));
        }
        MotorThermal net(p, std::stod(argv[1]));
        double h, E_cu, E_fe;
        StepConditions at;
        while (std::scanf("%lf,%lf,%lf,%lf,%lf,%lf,%lf", &h, &E_cu, &E_fe, &at.w_m, &at.I_rms, &at.T_coolant,
                          &at.T_ambient) == 7) {
            net.advance(h, E_cu, E_fe, at);
            const NodeVector& t = net.theta();
            std::printf("%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", t[0], t[1], t[2], t[3], net.E_loss(),
                        net.E_stored(), net.E_coolant(), net.E_ambient());
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "thermal_trace: %s\n", e.what());
        return 2;
    }
}
