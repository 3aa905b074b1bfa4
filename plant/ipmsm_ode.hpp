// The saturated IPMSM's electrical equations in rotor (dq) coordinates, free of FMI and of the
// integrator. States are the flux linkages; the currents are the flux map's exact inverse at them
// (machine/inverse_flux_map.hpp: Newton on the map from a table built once):
//
//     d psi_d / dt = u_d - R i_d + omega psi_q
//     d psi_q / dt = u_q - R i_q - omega psi_d,     i = i_map(psi_d - delta_psi_m, psi_q)
//
// Conventions (docs/spec/MATH.md): amplitude-invariant dq, peak values, PM flux on +d,
// omega = p w_m, T_e = 1.5 p (psi_d i_q - psi_q i_d). A magnet temperature other than the map's
// shifts the PM flux by delta_psi_m = psi_m k_psi_T (T_magnet - T_magnet_ref) (magnet_flux.hpp):
// the forward map becomes psi(i) + (delta_psi_m, 0), its inverse i(psi_d - delta_psi_m, psi_q).
//
// Power balance (exact for these equations, 1.5 from the amplitude-invariant transform):
//     P_elec = 1.5 (u_d i_d + u_q i_q) = 1.5 i . dpsi/dt + 1.5 R |i|^2 + T_e w_m
// i.e. input power = rate of magnetic energy + copper loss + air-gap power. Iron loss is not in
// the electrical equations: it is a drag on the shaft, T_shaft = T_e - P_fe / w_m, so that
// P_mech = T_shaft w_m = T_e w_m - P_fe.
#pragma once

#include <cmath>

#include "machine/iron_loss.hpp"
#include "machine/inverse_flux_map.hpp"
#include "machine/iron_loss.hpp"

namespace ipmsm {

// The right-hand side with its inputs held (they are piecewise constant between communication
// points). Plain data: the inverse map is borrowed, its owner keeps it alive.
struct DqFluxOde {
    const InverseFluxMap* inverse = nullptr;
    double u_d = 0, u_q = 0;  // V
    double omega = 0;         // electrical speed p w_m, rad/s
    double R = 0;             // stator resistance at the winding temperature, Ohm
    double delta_psi_m = 0;   // PM flux change from magnet temperature, Wb

    InverseFluxPoint currents(double psi_d, double psi_q) const { return inverse->eval(psi_d - delta_psi_m, psi_q); }
    // ... with Newton started from a guess of the currents (inverse_flux_map.hpp: eval_near).
    InverseFluxPoint currents_near(double psi_d, double psi_q, double i_d_guess, double i_q_guess) const {
        return inverse->eval_near(psi_d - delta_psi_m, psi_q, i_d_guess, i_q_guess);
    }
    void rhs(const double* psi, double* dpsi) const {
        const InverseFluxPoint c = currents(psi[0], psi[1]);
        dpsi[0] = u_d - R * c.i_d + omega * psi[1];
        dpsi[1] = u_q - R * c.i_q - omega * psi[0];
    }
    // d(dpsi/dt)/d psi, row-major: J[0] = d f_d/d psi_d, J[1] = d f_d/d psi_q, J[2], J[3] for f_q.
    void jacobian(const double* psi, double* J) const {
        double f[2];
        rhs_and_jacobian(psi, f, J);
    }
    // ... and the currents there (optional), from the same inverse-map evaluation.
    void rhs_and_jacobian(const double* psi, double* dpsi, double* J, InverseFluxPoint* at = nullptr) const {
        const InverseFluxPoint c = currents(psi[0], psi[1]);
        if (at != nullptr) *at = c;
        rhs_and_jacobian(psi, c, dpsi, J);
    }
    // ... at the currents c = currents(psi) known already.
    void rhs_and_jacobian(const double* psi, const InverseFluxPoint& c, double* dpsi, double* J) const {
        dpsi[0] = u_d - R * c.i_d + omega * psi[1];
        dpsi[1] = u_q - R * c.i_q - omega * psi[0];
        J[0] = -R * c.G_dd;
        J[1] = -R * c.G_dq + omega;
        J[2] = -R * c.G_qd - omega;
        J[3] = -R * c.G_qq;
    }
};

// What the plant integrates over each step alongside the flux linkages (CVODE quadratures,
// cvode_integrator.hpp): the electrical input power, the copper and iron losses (W) and the
// electromagnetic torque (N.m), at flux linkages psi whose currents are i. Their integrals are the
// step's energies (J) and the torque's impulse (N.m.s); with w_m held over the step, the shaft
// energy is w_m int T_e - int P_fe and the shaft torque's impulse int T_e - int P_fe / w_m.
struct StepIntegrands {
    enum Index { P_elec, P_cu, P_fe, T_e, count };
    int pole_pairs = 1;
    double w_m = 0;  // rad/s, mechanical
    IronLossModel fe;

    void eval(const DqFluxOde& ode, double psi_d, double psi_q, double i_d, double i_q, double* q) const {
        q[P_elec] = 1.5 * (ode.u_d * i_d + ode.u_q * i_q);
        q[P_cu] = 1.5 * ode.R * (i_d * i_d + i_q * i_q);
        q[P_fe] = fe.power(pole_pairs, w_m, psi_d, psi_q);
        q[T_e] = 1.5 * pole_pairs * (psi_d * i_q - psi_q * i_d);
    }
};

// Everything the plant reports at one instant.
struct PlantOutputs {
    double i_d, i_q;        // A
    double T_e, T_shaft;    // N.m
    double P_elec, P_mech;  // W
    double P_cu, P_fe;      // W
};

// At flux linkages psi whose currents i are known (from the inverse map, or exactly).
inline PlantOutputs plant_outputs(const DqFluxOde& ode, int pole_pairs, double w_m, const IronLossModel& fe,
                                  double psi_d, double psi_q, double i_d, double i_q) {
    double q[StepIntegrands::count];
    StepIntegrands{pole_pairs, w_m, fe}.eval(ode, psi_d, psi_q, i_d, i_q, q);
    PlantOutputs o;
    o.i_d = i_d;
    o.i_q = i_q;
    o.T_e = q[StepIntegrands::T_e];
    o.P_elec = q[StepIntegrands::P_elec];
    o.P_cu = q[StepIntegrands::P_cu];
    o.P_fe = q[StepIntegrands::P_fe];
    const double drag = w_m != 0.0 ? o.P_fe / w_m : 0.0;  // iron-loss drag torque, sign of w_m
    o.T_shaft = o.T_e - drag;
    o.P_mech = o.T_shaft * w_m;
    return o;
}

inline PlantOutputs plant_outputs(const DqFluxOde& ode, int pole_pairs, double w_m, const IronLossModel& fe,
                                  double psi_d, double psi_q) {
    const InverseFluxPoint c = ode.currents(psi_d, psi_q);
    return plant_outputs(ode, pole_pairs, w_m, fe, psi_d, psi_q, c.i_d, c.i_q);
}

}  // namespace ipmsm
