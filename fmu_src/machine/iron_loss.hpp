// Iron loss of the default motor's model (seed eq. 13, docs/motor/README.md):
//     P_fe = k_h f b^alpha + k_e f^2 b^2,   f = p |w_m| / (2 pi),   b = |psi| / psi_ref.
// Its parameters are a part a model holds (the plant: its loss and shaft drag); their FMI
// variables (fe_k_h, fe_alpha, fe_k_e, fe_psi_ref) are declared once (parts/part_variables.cpp).
#pragma once

#include <cmath>

namespace ipmsm {

struct IronLossModel {
    double k_h = 0;      // W/Hz
    double alpha = 2;    // 1
    double k_e = 0;      // W/Hz^2
    double psi_ref = 1;  // Wb

    double power(int pole_pairs, double w_m, double psi_d, double psi_q) const {
        const double f = pole_pairs * std::abs(w_m) / (2.0 * 3.14159265358979323846);
        if (f == 0.0) return 0.0;
        const double b = std::sqrt(psi_d * psi_d + psi_q * psi_q) / psi_ref;
        const double b2 = b * b;
        return k_h * f * (alpha == 2.0 ? b2 : std::pow(b, alpha)) + k_e * f * f * b2;
    }
};

// The default motor's (docs/motor/README.md; the default map's metadata state the same).
inline constexpr IronLossModel kDefaultMotorIronLoss{1.06664735685, 2.0, 0.00581807649193, 0.0780669432093};

}  // namespace ipmsm
