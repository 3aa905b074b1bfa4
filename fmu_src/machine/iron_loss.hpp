// Iron loss of the machine (seed eq. 13, docs/motor/README.md): the one implementation, used by
// the plant (its P_fe, plant/ipmsm_ode.hpp) and by the controller's least-loss commands
// (control/least_loss.hpp), so that what the controller minimises is what the plant dissipates:
//
//     P_fe = k_h f b^alpha + k_e f^2 b^2,   f = p |w_m| / (2 pi),   b = |psi| / psi_ref
//
// Its parameters are a part a model holds (the plant: its loss and shaft drag; the controller: its
// least-loss commands); their FMI variables (fe_k_h, fe_alpha, fe_k_e, fe_psi_ref) are declared
// once (parts/part_variables.cpp).
#pragma once

#include <cmath>

namespace ipmsm {

// P_fe as a function of the squared flux-linkage magnitude s = |psi|^2 (Wb^2) at a fundamental
// frequency f, with its first two derivatives in s (what Newton on the map needs).
struct IronLossAtFlux {
    double P = 0;     // W
    double dP = 0;    // W/Wb^2
    double d2P = 0;   // W/Wb^4
};

struct IronLossModel {
    double k_h = 0;      // W/Hz
    double alpha = 2;    // 1
    double k_e = 0;      // W/Hz^2
    double psi_ref = 1;  // Wb

    static double frequency(int pole_pairs, double w_m) {
        return pole_pairs * std::abs(w_m) / (2.0 * 3.14159265358979323846);
    }
    double power(int pole_pairs, double w_m, double psi_d, double psi_q) const {
        const double f = frequency(pole_pairs, w_m);
        if (f == 0.0) return 0.0;
        return power_at(f, psi_d * psi_d + psi_q * psi_q);
    }
    // At frequency f > 0 (Hz) and |psi|^2 = s.
    double power_at(double f, double s) const {
        const double b = std::sqrt(s) / psi_ref;
        const double b2 = b * b;
        return k_h * f * (alpha == 2.0 ? b2 : std::pow(b, alpha)) + k_e * f * f * b2;
    }
    // ... and its derivatives in s. b^alpha = (s / psi_ref^2)^(alpha/2): for alpha < 2 its
    // derivatives grow without bound as s -> 0 (no flux), which the solvers never reach with a
    // magnet, and avoid without (least_loss.cpp).
    IronLossAtFlux derivatives_at(double f, double s) const {
        IronLossAtFlux r;
        r.P = power_at(f, s);
        if (f == 0.0) return r;
        const double inv_ref2 = 1.0 / (psi_ref * psi_ref);
        const double ce = k_e * f * f * inv_ref2;  // d(k_e f^2 b^2)/ds
        if (alpha == 2.0) {
            r.dP = k_h * f * inv_ref2 + ce;
            return r;
        }
        const double h = 0.5 * alpha;
        const double x = s * inv_ref2;  // b^2
        const double xh = std::pow(x, h - 1.0);
        r.dP = k_h * f * h * xh * inv_ref2 + ce;
        r.d2P = x > 0.0 ? k_h * f * h * (h - 1.0) * xh / x * inv_ref2 * inv_ref2 : 0.0;
        return r;
    }
};

// The default motor's (docs/motor/README.md; the default map's metadata state the same).
inline constexpr IronLossModel kDefaultMotorIronLoss{1.06664735685, 2.0, 0.00581807649193, 0.0780669432093};

}  // namespace ipmsm
