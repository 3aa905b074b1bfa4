// The drive's steady-state loss at a current command, for the controller (its least-loss commands
// and P_loss_cmd): copper + iron + inverter with the plant's own models at the controller's
// parameters, the one implementation of each (machine/iron_loss.hpp, inverter/inverter_loss.hpp):
//
//     P_cu  = 1.5 R |i|^2                      (R at the winding's temperature)
//     P_fe  = k_h f b^alpha + k_e f^2 b^2       (b = |psi(i)| / psi_ref, the map at the magnets' temperature)
//     P_inv = the inverter's conduction and switching loss at u_dc, P_ac = T_e w_m + P_cu
//
// and the shaft torque T_e - P_fe / w_m (docs/spec/MATH.md, "Least-loss control").
#pragma once

#include <cmath>

#include "inverter/inverter_loss.hpp"
#include "machine/iron_loss.hpp"

namespace ipmsm {

struct LossSplit {
    double P_cu = 0, P_fe = 0, P_inv = 0;  // W
    double total() const { return P_cu + P_fe + P_inv; }
};

// The loss model at one operating condition (speed, winding resistance, DC voltage).
class DriveLoss {
public:
    DriveLoss(const IronLossModel& iron, const InverterParams& inverter, int pole_pairs, double w_m, double R,
              double u_dc)
        : iron_(iron), inverter_(inverter, u_dc), pole_pairs_(pole_pairs), w_m_(w_m), R_(R),
          f_(IronLossModel::frequency(pole_pairs, w_m)) {}

    // At a current i whose flux linkage (the magnets' temperature included) is psi and torque T_e.
    LossSplit at(double i_d, double i_q, double psi_d, double psi_q, double T_e) const {
        LossSplit l;
        const double c = i_d * i_d + i_q * i_q;
        l.P_cu = 1.5 * R_ * c;
        l.P_fe = iron_.power(pole_pairs_, w_m_, psi_d, psi_q);
        l.P_inv = inverter_.at(std::sqrt(c), c, T_e * w_m_ + l.P_cu).P();
        return l;
    }
    // The iron-loss drag on the shaft, P_fe / w_m (N.m, the sign of w_m; 0 at standstill).
    double drag(double P_fe) const { return w_m_ != 0.0 ? P_fe / w_m_ : 0.0; }

    const IronLossModel& iron() const { return iron_; }
    const InverterLossModel& inverter() const { return inverter_; }
    double frequency() const { return f_; }  // Hz, electrical
    double w_m() const { return w_m_; }
    double R() const { return R_; }

private:
    IronLossModel iron_;
    InverterLossModel inverter_;
    int pole_pairs_;
    double w_m_, R_, f_;
};

}  // namespace ipmsm
