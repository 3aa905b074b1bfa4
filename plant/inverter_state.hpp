// What the inverter does to the machine's terminals (docs/spec/INTERFACE.md, "Faults";
// docs/spec/MATH.md, "The inverter's safe states"): switching (the average voltage u_d, u_q
// applied), freewheeling (all gates off: the six diodes rectify into u_dc) and the active short
// circuit (u = 0). Free of FMI and of the integrator.
//
// Freewheeling at the fundamental frequency (T. M. Jahns and V. Caliskan, "Uncontrolled
// generator operation of interior PM synchronous machines following high-speed inverter
// shutdown", IEEE Trans. Ind. Appl. 35(6), 1999): while the bridge conducts, its six-step
// voltage's fundamental is in phase with the current, u = -k i/|i|, k = 2 u_dc / pi. It blocks
// (i = 0, psi = psi_0 = psi(0, 0) with the magnet's temperature shift) otherwise. With i = 0 the
// back-EMF is e_0 = omega (psi_0q, -psi_0d), |e_0| = |omega| |psi_0|. Near i = 0 the currents
// follow di/dt = G_0 (e_0 - k n), n = i/|i|, G_0 = L_0^-1 the incremental inverse inductance at
// zero current; a current of direction n grows or decays along itself only where
//     e_0 = (k I + lambda L_0) n,   |n| = 1,
// d|i|/dt = lambda. A solution with lambda > 0 (the onset direction: conduction starts along it)
// exists exactly when |e_0| > k: the fundamental model's onset is |omega| |psi_0| = 2 u_dc / pi.
// Solutions with lambda < 0 are the directions along which a decaying current reaches zero, in
// finite time: one near e_0 exactly when |e_0| < k (the bridge then blocks), and near -e_0 at any
// speed (a current driven against the back-EMF, extinguished head-on; above the onset it passes
// zero and grows again along the onset direction). The same condition both ways: no chattering.
#pragma once

#include <cmath>

namespace ipmsm {

enum class InverterState : int { switching = 0, freewheeling = 1, asc = 2 };

constexpr double kPiBridge = 3.14159265358979323846;

// The diode bridge's fundamental voltage amplitude while it conducts (V): the six-step phase
// voltage's fundamental, 2 u_dc / pi.
inline double bridge_amplitude(double u_dc) { return 2.0 * u_dc / kPiBridge; }

// The DC-link current of the conducting bridge (A, + into the machine): P_elec / u_dc with
// P_elec = 1.5 u . i = -(3/pi) u_dc |i|.
inline double bridge_dc_current(double i_abs) { return -(3.0 / kPiBridge) * i_abs; }

// The diodes' conduction loss (W) at a phase-current peak I (A) and I2 = I^2: each leg's current
// is carried by one diode all the time, V_D0 2I/pi + r_D I^2/2 per leg (inverter/inverter_loss.hpp
// with the IGBTs' share zero).
inline double diode_bridge_loss(double V_D0, double r_D, double I, double I2) {
    return (6.0 / kPiBridge) * V_D0 * I + 1.5 * r_D * I2;
}

// The directions along which a current leaves or reaches zero (above): every unit n with
// e0 = (k I + lambda L0) n, L0 row-major (d psi / d i at zero current). n rotates with the angle
// theta; (L0 n) x (e0 - k n) = 0 there, and lambda = (e0 - k n) . L0 n / |L0 n|^2. The roots in
// theta are bracketed on kBridgeAngles samples of the turn and refined by bisection.
struct BridgeDirections {
    int n_decay = 0;           // directions along which a decaying current reaches zero (lambda < 0)
    double decay[4][2] = {};   // ... their unit vectors
    bool has_onset = false;    // a growing direction (lambda > 0): |e0| > k, conduction starts
    double onset[2] = {0, 0};  // ... its unit vector
};

constexpr int kBridgeAngles = 720;

inline BridgeDirections bridge_directions(const double* e0, double k, const double* L0) {
    auto cross = [&](double th) {
        const double nd = std::cos(th), nq = std::sin(th);
        const double ld = L0[0] * nd + L0[1] * nq, lq = L0[2] * nd + L0[3] * nq;
        return ld * (e0[1] - k * nq) - lq * (e0[0] - k * nd);
    };
    BridgeDirections out;
    const double step = 2.0 * kPiBridge / kBridgeAngles;
    double a = 0.0, fa = cross(a);
    for (int j = 1; j <= kBridgeAngles; ++j) {
        const double b = j * step, fb = cross(b);
        if ((fa < 0.0) != (fb < 0.0)) {
            double lo = a, hi = b, flo = fa;
            for (int it = 0; it < 60 && flo != 0.0; ++it) {
                const double mid = 0.5 * (lo + hi), fm = cross(mid);
                if ((fm < 0.0) == (flo < 0.0)) {
                    lo = mid;
                    flo = fm;
                } else {
                    hi = mid;
                }
            }
            const double th = flo == 0.0 ? lo : 0.5 * (lo + hi);
            const double n[2] = {std::cos(th), std::sin(th)};
            const double l[2] = {L0[0] * n[0] + L0[1] * n[1], L0[2] * n[0] + L0[3] * n[1]};
            const double lambda = ((e0[0] - k * n[0]) * l[0] + (e0[1] - k * n[1]) * l[1]) / (l[0] * l[0] + l[1] * l[1]);
            if (lambda > 0.0) {
                out.has_onset = true;
                out.onset[0] = n[0], out.onset[1] = n[1];
            } else if (lambda < 0.0 && out.n_decay < 4) {
                out.decay[out.n_decay][0] = n[0];
                out.decay[out.n_decay][1] = n[1];
                ++out.n_decay;
            }
        }
        a = b;
        fa = fb;
    }
    return out;
}

}  // namespace ipmsm
