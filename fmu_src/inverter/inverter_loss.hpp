// Traction-inverter losses: a two-level, three-phase IGBT bridge with anti-parallel diodes,
// sinusoidal phase currents of peak I, continuous PWM at f_sw (every leg switches every period).
// The one implementation: the IpmsmPlant's loss P_inv per step (plant/plant_model.cpp), which
// IpmsmDrive reads per inner step and the reference loop reads from the plant FMU by name.
//
// Conduction, each device a threshold voltage plus a slope resistance (V = V0 + r i), averaged
// over the fundamental period and summed over the three legs:
//
//     P_cond = (3/pi)(V_T0 + V_D0) I + (3/4)(r_T + r_D) I^2 + (V_T0 - V_D0) P_ac / u_dc
//
// In each leg the phase current is always carried by one device (IGBT or the opposite diode),
// which gives the first two terms whatever the modulation; the IGBT/diode share changes the
// threshold-voltage term by exactly (V_T0 - V_D0) times the mean DC current P_ac / u_dc (the
// legs' mean duty-weighted currents sum to it). The matching (r_T - r_D) term is left out
// (< 1 % of the loss with the defaults).
//
// Switching, the datasheet energies scaled linearly with current and with DC voltage to the
// power k_v, each leg hard-switching |i| once per period:
//
//     P_sw = (6/pi) f_sw (E_on + E_off + E_rec) (I / I_ref) (u_dc / V_ref)^k_v
//
// Every term is linear in I, I^2 or P_ac: the loss of the means over an interval is the mean of
// the losses (at a held u_dc), so a caller may average either.
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>

namespace ipmsm {

// Datasheet-class values of a 750 V / 820 A automotive IGBT six-pack (Infineon HybridPACK Drive
// FS820R08A6P2B class, EDT2 IGBT), typical at T_vj = 150 C; V0 and r from straight lines through
// the output characteristic between ~1/4 and full nominal current (docs/vehicle.md).
struct InverterParams {
    double V_T0 = 0.70;    // V, IGBT threshold voltage (V_CE,sat ~ 1.2 V at 820 A)
    double r_T = 0.60e-3;  // Ohm, IGBT slope resistance
    double V_D0 = 0.80;    // V, diode threshold voltage (V_F ~ 1.37 V at 820 A)
    double r_D = 0.70e-3;  // Ohm, diode slope resistance
    double E_on = 28e-3;   // J per turn-on at I_ref, V_ref
    double E_off = 42e-3;  // J per turn-off at I_ref, V_ref
    double E_rec = 18e-3;  // J per diode reverse recovery at I_ref, V_ref
    double I_ref = 820.0;  // A, test current of the switching energies
    double V_ref = 400.0;  // V, test DC voltage of the switching energies
    double k_v = 1.0;      // exponent of the voltage scaling
    double f_sw = 10e3;    // Hz: one PWM period per controller sample (100 us)
};

struct InverterLoss {
    double P_cond = 0.0;  // W
    double P_sw = 0.0;    // W
    double P() const { return P_cond + P_sw; }
};

// The loss model at a DC voltage u_dc (V): what u_dc fixes, computed once (a caller stepping many
// PWM periods at a held u_dc evaluates only the terms in I, I^2 and P_ac).
class InverterLossModel {
public:
    InverterLossModel(const InverterParams& p, double u_dc) : p_(p), u_dc_(u_dc) {
        if (!(u_dc > 0.0))
            throw std::invalid_argument("inverter loss: bad DC voltage u_dc = " + std::to_string(u_dc) + " V");
        constexpr double kPi = 3.14159265358979323846;
        k_I_ = (3.0 / kPi) * (p.V_T0 + p.V_D0);
        k_I2_ = 0.75 * (p.r_T + p.r_D);
        k_sw_ = (6.0 / kPi) * p.f_sw * (p.E_on + p.E_off + p.E_rec) / p.I_ref * std::pow(u_dc / p.V_ref, p.k_v);
    }
    // Loss (W) with the phase-current peak |i| = I (A), |i|^2 = I2 (A^2) and AC power P_ac (W,
    // + motoring); or their means over an interval.
    InverterLoss at(double I, double I2, double P_ac) const {
        if (!(I >= 0.0) || !(I2 >= 0.0))
            throw std::invalid_argument("inverter loss: bad operating point |i| = " + std::to_string(I) +
                                        " A, |i|^2 = " + std::to_string(I2) + " A^2, u_dc = " + std::to_string(u_dc_) +
                                        " V");
        InverterLoss l;
        l.P_cond = k_I_ * I + k_I2_ * I2 + (p_.V_T0 - p_.V_D0) * P_ac / u_dc_;
        l.P_sw = k_sw_ * I;
        return l;
    }

    // The loss as k_linear |i| + k_square |i|^2 + k_ac P_ac: its coefficients at this u_dc (W/A,
    // W/A^2, 1), for a caller minimising it (control/least_loss.hpp).
    double k_linear() const { return k_I_ + k_sw_; }
    double k_square() const { return k_I2_; }
    double k_ac() const { return (p_.V_T0 - p_.V_D0) / u_dc_; }

private:
    InverterParams p_;
    double u_dc_;
    double k_I_ = 0, k_I2_ = 0, k_sw_ = 0;  // W/A, W/A^2, W/A
};

}  // namespace ipmsm
