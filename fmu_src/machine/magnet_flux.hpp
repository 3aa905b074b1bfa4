// The flux map at a magnet temperature: NdFeB remanence falls with temperature, so the PM flux
// linkage scales as psi_m(T) = psi_m(T_ref) (1 + k_psi_T (T - T_ref)). We apply it as a shift of
// psi_d by the change of psi_m, which keeps the inductances (and reciprocity) of the map.
#pragma once

#include "machine/flux_map.hpp"

namespace ipmsm {

inline double magnet_flux_shift(const FluxMap& map, double k_psi_T, double T_magnet, double T_magnet_ref) {
    return map.psi_m() * k_psi_T * (T_magnet - T_magnet_ref);
}

class MagnetFlux {
public:
    MagnetFlux(const FluxMap& map, double psi_d_shift) : map_(map), shift_(psi_d_shift) {}
    FluxPoint eval(double i_d, double i_q) const {
        FluxPoint p = map_.eval(i_d, i_q);
        p.psi_d += shift_;
        return p;
    }
    FluxPoint2 eval2(double i_d, double i_q) const {
        FluxPoint2 p = map_.eval2(i_d, i_q);
        p.psi_d += shift_;
        return p;
    }
    // Reduced torque psi_d i_q - psi_q i_d (T = 1.5 p times this).
    double reduced_torque(double i_d, double i_q) const {
        const FluxPoint p = eval(i_d, i_q);
        return p.psi_d * i_q - p.psi_q * i_d;
    }
    const FluxMap& map() const { return map_; }
    double shift() const { return shift_; }

private:
    const FluxMap& map_;
    double shift_;
};

}  // namespace ipmsm
