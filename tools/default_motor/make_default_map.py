"""Write the default motor's flux map: fmu_src/resources/ev_ipmsm_default.csv.

    python -m tools.default_motor.make_default_map            (from the repository root)
    python -m tools.default_motor.make_default_map --out FILE

The motor: a C-segment EV traction IPMSM with the seed paper's main dimensions (8 poles, stator
249 mm, rotor 171 mm, stack 120 mm, air gap 0.8 mm), for a 355 V (96s NMC) DC link and 500 A peak.
Its flux linkages come from the energy-consistent model in saturation.py, its iron loss from
iron_loss.py; everything else (resistance, temperature coefficients, limits) is in MotorData.
The output is deterministic: the tests regenerate it and compare with the shipped file.
"""
from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenarios.core.constants import T_REFERENCE_K, U_DC_NOMINAL_V
from scenarios.maps.flux_map import DEFAULT_MAP

from . import iron_loss, saturation


@dataclass(frozen=True)
class MotorData:
    """The default motor: everything the map file carries besides the flux linkages."""

    pole_pairs: int = 4  # 8 poles, as the seed's motor
    # geometry (seed paper, Sec. II-A); used here for the iron mass only
    d_stator_outer_m: float = 0.249
    d_rotor_outer_m: float = 0.171
    air_gap_m: float = 0.8e-3
    l_stack_m: float = 0.120
    # winding: 12 mOhm phase resistance at 20 degC, in the 10-20 mOhm range of ~100 kW 8-pole
    # traction IPMSMs at this size (e.g. Nissan Leaf EM57 class); 4.5 kW copper loss at I_max
    R_s_ohm: float = 0.012
    T_winding_ref_K: float = T_REFERENCE_K  # R_s given at 20 degC
    alpha_cu_per_K: float = 0.00393  # copper, +0.393 %/K
    # magnets: NdFeB remanence falls ~0.12 %/K (sintered N-grade); the map holds at 20 degC
    T_magnet_ref_K: float = T_REFERENCE_K
    k_psi_T_per_K: float = -0.0012
    # drive limits: 96s NMC pack at 3.7 V/cell nominal = 355 V; inverter 500 A peak (354 A rms)
    I_max_A: float = 500.0
    u_dc_V: float = U_DC_NOMINAL_V
    k_u: float = 0.95  # V_max = k_u u_dc / sqrt(3), linear SVPWM with regulator headroom
    n_max_rpm: float = 12000.0
    saturation: saturation.SaturationParams = field(default_factory=saturation.SaturationParams)
    # iron loss: M270-35A stator core, 38 % of the annulus is slots, effective peak flux density
    # 1.5 T at no load (teeth ~1.7 T, yoke ~1.4 T), build factor 1.8 (see iron_loss.py)
    lamination: iron_loss.Lamination = iron_loss.M270_35A
    slot_fraction: float = 0.38
    b_ref_T: float = 1.5
    build_factor: float = 1.8
    # map grid: i_d from -1.4 I_max to +0.6 I_max, i_q from -1.4 I_max to +1.4 I_max, 20 A steps
    grid_step_A: float = 20.0
    i_d_range_A: tuple = (-700.0, 300.0)
    i_q_range_A: tuple = (-700.0, 700.0)

    @property
    def w_m_max_rad_s(self) -> float:
        return self.n_max_rpm * math.pi / 30

    @property
    def psi_m_Wb(self) -> float:
        """PM flux linkage psi_d(0, 0) at T_magnet_ref."""
        return float(saturation.flux_from_current(0.0, 0.0, self.saturation)[0])

    @property
    def iron_mass_kg(self) -> float:
        d_bore = self.d_rotor_outer_m + 2 * self.air_gap_m
        return iron_loss.stator_core_mass(self.d_stator_outer_m, d_bore, self.l_stack_m, self.slot_fraction)

    @property
    def iron_loss(self) -> iron_loss.IronLossCoefficients:
        return iron_loss.machine_coefficients(
            self.lamination, self.iron_mass_kg, self.b_ref_T, self.build_factor, psi_ref=self.psi_m_Wb
        )

    def grid(self):
        """The map's axes (A): i_d, i_q."""
        s = self.grid_step_A
        i_d = np.arange(self.i_d_range_A[0], self.i_d_range_A[1] + s / 2, s)
        i_q = np.arange(self.i_q_range_A[0], self.i_q_range_A[1] + s / 2, s)
        return i_d, i_q


def _g(x: float) -> str:
    return f"{x:.12g}"


def metadata(motor: MotorData) -> dict:
    """The '# key: value' lines of the file (numbers as written)."""
    fe = motor.iron_loss
    return {
        "pole_pairs": str(motor.pole_pairs),
        "R_s_ohm": _g(motor.R_s_ohm),
        "T_winding_ref_K": _g(motor.T_winding_ref_K),
        "alpha_cu_per_K": _g(motor.alpha_cu_per_K),
        "T_magnet_ref_K": _g(motor.T_magnet_ref_K),
        "k_psi_T_per_K": _g(motor.k_psi_T_per_K),
        "I_max_A": _g(motor.I_max_A),
        "u_dc_V": _g(motor.u_dc_V),
        "k_u": _g(motor.k_u),
        "w_m_max_rad_s": _g(motor.w_m_max_rad_s),
        "psi_m_Wb": _g(motor.psi_m_Wb),
        "fe_k_h_W_per_Hz": _g(fe.k_h),
        "fe_alpha": _g(fe.alpha),
        "fe_k_e_W_per_Hz2": _g(fe.k_e),
        "fe_psi_ref_Wb": _g(fe.psi_ref),
    }


def csv_text(motor: MotorData | None = None) -> str:
    """The whole CSV file as text (of the default motor unless told otherwise)."""
    motor = motor if motor is not None else MotorData()
    sat = motor.saturation
    i_d, i_q = motor.grid()
    d, q = np.meshgrid(i_d, i_q, indexing="ij")  # i_d outer, i_q inner in the rows below
    psi_d, psi_q = saturation.flux_from_current(d, q, sat)
    # Free-text lines avoid 'word: ' so that no reader takes them for metadata.
    lines = [
        "# Default motor of ipmsm-fmu - a C-segment EV traction IPMSM (synthetic, not measured).",
        "# Generated by 'python -m tools.default_motor.make_default_map' (tools/default_motor/), do not edit by hand.",
        "# Machine = 8 poles, V-shaped NdFeB magnets, stator OD 249 mm, rotor OD 171 mm, stack 120 mm,",
        f"#   air gap 0.8 mm (the main dimensions of the seed paper's EV motor). Drive = {motor.u_dc_V:g} V DC link",
        f"#   (96s NMC), {motor.I_max_A:g} A peak, {motor.n_max_rpm:g} r/min. "
        "Targets >= 250 N.m, >= 100 kW; the values",
        "#   measured on this map are in docs/motor/README.md (python -m tools.default_motor.check_targets).",
        "# Convention = amplitude-invariant dq, peak values, PM flux on +d, T = 1.5 p (psi_d i_q - psi_q i_d).",
        "# Saturation model = magnetic energy of Hinkkanen et al. (IEEE TIA 2017, doi 10.1109/TIA.2016.2644624)",
        "#   W(psi) = a_d0/2 psi_d^2 + a_dd/(S+2) |psi_d|^(S+2) + a_q0/2 psi_q^2 + a_qq/(T+2) |psi_q|^(T+2)",
        "#          + a_dq/((U+2)(V+2)) |psi_d|^(U+2) |psi_q|^(V+2),",
        "#   i_d = dW/dpsi_d - i_f, i_q = dW/dpsi_q, the magnet being an equivalent d-axis current i_f.",
        "#   Currents are a gradient, so the map is reciprocal (dpsi_d/di_q = dpsi_q/di_d) by construction;",
        "#   the PM flux linkage falls with |i_q| (cross-saturation). psi(i) is solved by Newton's method.",
        f"#   a_d0 = {_g(sat.a_d0)} A/Wb, a_dd = {_g(sat.a_dd)}, S = {_g(sat.S)}, a_q0 = {_g(sat.a_q0)} A/Wb,"
        f" a_qq = {_g(sat.a_qq)}, T = {_g(sat.T)},",
        f"#   a_dq = {_g(sat.a_dq)}, U = {_g(sat.U)}, V = {_g(sat.V)}, i_f = {_g(sat.i_f)} A"
        " (a_xx in A/Wb^(exponent+1)).",
        "# Temperatures = R_s(T_w) = R_s_ohm (1 + alpha_cu_per_K (T_w - T_winding_ref_K));",
        "#   magnet flux scales by (1 + k_psi_T_per_K (T_m - T_magnet_ref_K)). The map holds at T_magnet_ref_K.",
        "# Iron loss (seed eq. 13) = P_fe = fe_k_h_W_per_Hz f b^fe_alpha + fe_k_e_W_per_Hz2 f^2 b^2 in W,",
        "#   f = p |w_m| / (2 pi) electrical frequency in Hz, b = sqrt(psi_d^2 + psi_q^2) / fe_psi_ref_Wb.",
        f"#   From M270-35A steel (2.70 W/kg at 1.5 T 50 Hz, 24 W/kg at 1.0 T 400 Hz), {motor.iron_mass_kg:.1f} kg"
        f" stator core, {motor.b_ref_T:g} T at psi_m, build factor {motor.build_factor:g}.",
        "# Limits = I_max_A peak current, V_max = k_u u_dc_V / sqrt(3), w_m_max_rad_s maximum speed;",
        "#   psi_m_Wb = psi_d(0, 0), for information.",
    ]
    lines += [f"# {k}: {v}" for k, v in metadata(motor).items()]
    lines.append("i_d,i_q,psi_d,psi_q")
    for a, b, c, e in zip(d.ravel(), q.ravel(), psi_d.ravel(), psi_q.ravel()):
        lines.append(f"{a:g},{b:g},{c:.12g},{e:.12g}")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=DEFAULT_MAP, help=f"output file (default {DEFAULT_MAP})")
    args = ap.parse_args(argv)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(csv_text(MotorData()))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
