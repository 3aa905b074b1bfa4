"""Flux maps of strongly saturating IPMSMs, for testing: a family of legal maps in the contract's
CSV format (full rectangular grid, peak A and Wb, PM flux on +d), monotone and exactly
reciprocal, whose q-axis flux levels off hard at high current as FEM maps of traction motors do.

    python -m tools.saturating_map --I-s-ratio 0.3 --out map.csv
    python -m tools.saturating_map --I-s-ratio 0.2 --I-ds-ratio 0.5 --cross 0.15 --out map.csv

Model: one magnetic co-energy W(i_d, i_q), the fluxes its gradient,

    psi_d = dW/di_d,   psi_q = dW/di_q,

so that dpsi_d/di_q = dpsi_q/di_d = d2W/(di_d di_q) (Schwarz): the map is reciprocal by
construction (a lossless magnetic system has a co-energy whose gradient is the flux linkage;
e.g. Krause et al., Analysis of Electric Machinery and Drive Systems, 3rd ed., sec. 1.3; the
energy form in flux linkage is Hinkkanen et al., IEEE TIA 53(3) 2017, doi
10.1109/TIA.2016.2644624, which the default motor uses). Here

    W = psi_m i_d + L_d F(i_d) + (1 - k_x tanh(i_d / I_x)) L_q G(i_q),
    G(i_q) = I_s^2 (sqrt(1 + (i_q / I_s)^2) - 1),      G'(i_q) = i_q / sqrt(1 + (i_q / I_s)^2),
    F(i_d) = i_d^2 / 2                                  (i_d <= 0, or no d-axis saturation),
    F(i_d) = I_ds^2 (sqrt(1 + (i_d / I_ds)^2) - 1)      (i_d > 0: d-axis saturation),

which gives, at i_d = 0, exactly psi_q = L_q i_q / sqrt(1 + (i_q/I_s)^2) (the issue's shape:
psi_q levels off at L_q I_s), psi_d = psi_m + L_d i_d for i_d <= 0 (without cross-saturation),
and the cross-saturation k_x: psi_q scaled by (1 - k_x tanh(i_d/I_x)) (less q flux as the d axis
saturates, more when field weakening relieves it) and, from the same W, the PM flux falling with
|i_q| by k_x L_q G(i_q) / (I_x cosh^2(i_d/I_x)). F is C2 at i_d = 0 (F'' = 1 on both sides).

Monotone means the incremental inductance matrix (the Hessian of W) is positive definite: the
plant needs currents as a function of flux linkages. make_map checks it on the grid and on a
finer one and refuses parameters that break it.
"""
from __future__ import annotations

import argparse
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from scenarios.maps.flux_map import FluxMap, write_flux_map

# Unsaturated machine constants near the project's default motor (fmu_src/resources/
# ev_ipmsm_default.csv: psi_m = 0.078 Wb, L_dd = 0.21 mH, L_qq = 0.57 mH at zero current).
PSI_M = 0.078       # Wb, PM flux linkage
L_D = 2.1e-4        # H, unsaturated d-axis inductance
L_Q = 5.7e-4        # H, unsaturated q-axis inductance
I_MAX = 500.0       # A peak, the drive's current limit (the default motor's)
POLE_PAIRS = 4
R_S = 0.012         # Ohm at T_WINDING_REF
U_DC = 355.0        # V, the default motor's DC link
K_U = 0.95          # V_max = k_u u_dc / sqrt 3
W_M_MAX = 1256.6370614359173  # rad/s (12 000 r/min)
T_REF = 293.15      # K, the map holds at this magnet and winding temperature
ALPHA_CU = 0.00393  # 1/K, copper
K_PSI_T = -0.0012   # 1/K, NdFeB remanence

# The grid spans +-GRID_SPAN_RATIO * I_max on both axes, so that I_max is well inside it.
GRID_SPAN_RATIO = 1.25
GRID_POINTS = 51
# Cross-saturation acts over i_d of the order of I_max.
CROSS_CURRENT_RATIO = 1.0
CROSS_MAX = 0.15  # the family's range (issue 12): cross-saturation up to 15 %


@dataclass(frozen=True)
class SaturatingMachine:
    """A strongly saturating IPMSM; SI units, peak amplitude-invariant dq."""

    I_s_ratio: float = 0.3              # q-axis saturation current I_s / I_max (0.2 ... 1)
    I_ds_ratio: float | None = None     # d-axis saturation current for i_d > 0 / I_max; None: none
    cross: float = 0.0                  # k_x, relative change of psi_q with i_d (0 ... 0.15)
    psi_m: float = PSI_M
    L_d: float = L_D
    L_q: float = L_Q
    I_max: float = I_MAX
    pole_pairs: int = POLE_PAIRS
    R_s: float = R_S
    grid_span_ratio: float = GRID_SPAN_RATIO
    grid_points: int = GRID_POINTS

    def __post_init__(self):
        if not 0.0 < self.I_s_ratio:
            raise ValueError(f"I_s_ratio must be positive, got {self.I_s_ratio}")
        if self.I_ds_ratio is not None and not 0.0 < self.I_ds_ratio:
            raise ValueError(f"I_ds_ratio must be positive or None, got {self.I_ds_ratio}")
        if not 0.0 <= self.cross < 1.0:
            raise ValueError(f"cross must be in [0, 1), got {self.cross}")
        if self.grid_span_ratio <= 1.0 or self.grid_points < 4:
            raise ValueError("the grid must span beyond I_max (grid_span_ratio > 1) with >= 4 points")

    @property
    def I_s(self) -> float:
        return self.I_s_ratio * self.I_max

    @property
    def I_x(self) -> float:
        return CROSS_CURRENT_RATIO * self.I_max

    # --- the co-energy's pieces and their derivatives
    def _G(self, i_q, order=0):
        r = np.sqrt(1.0 + (i_q / self.I_s) ** 2)
        return (self.I_s**2 * (r - 1.0), i_q / r, r**-3)[order]

    def _F(self, i_d, order=0):
        i_d = np.asarray(i_d, float)
        quad = (0.5 * i_d**2, i_d, np.ones_like(i_d))[order]
        if self.I_ds_ratio is None:
            return quad
        I_ds = self.I_ds_ratio * self.I_max
        r = np.sqrt(1.0 + (i_d / I_ds) ** 2)
        sat = (I_ds**2 * (r - 1.0), i_d / r, r**-3)[order]
        return np.where(i_d > 0, sat, quad)

    def _cross(self, i_d, order=0):
        """c(i_d) = 1 - k_x tanh(i_d / I_x) and its derivatives."""
        t = np.tanh(i_d / self.I_x)
        s2 = 1.0 - t**2
        return (1.0 - self.cross * t, -self.cross * s2 / self.I_x, 2.0 * self.cross * s2 * t / self.I_x**2)[order]

    def coenergy(self, i_d, i_q):
        """W(i_d, i_q), J."""
        return self.psi_m * i_d + self.L_d * self._F(i_d) + self._cross(i_d) * self.L_q * self._G(i_q)

    def flux(self, i_d, i_q):
        """(psi_d, psi_q) = grad W, Wb."""
        i_d, i_q = np.broadcast_arrays(np.asarray(i_d, float), np.asarray(i_q, float))
        psi_d = self.psi_m + self.L_d * self._F(i_d, 1) + self._cross(i_d, 1) * self.L_q * self._G(i_q)
        psi_q = self._cross(i_d) * self.L_q * self._G(i_q, 1)
        return psi_d, psi_q

    def inductances(self, i_d, i_q):
        """The Hessian of W: (L_dd, L_dq, L_qq), H (L_qd = L_dq: reciprocal)."""
        i_d, i_q = np.broadcast_arrays(np.asarray(i_d, float), np.asarray(i_q, float))
        L_dd = self.L_d * self._F(i_d, 2) + self._cross(i_d, 2) * self.L_q * self._G(i_q)
        L_dq = self._cross(i_d, 1) * self.L_q * self._G(i_q, 1)
        L_qq = self._cross(i_d) * self.L_q * self._G(i_q, 2)
        return L_dd, L_dq, L_qq

    def axis(self) -> np.ndarray:
        span = self.grid_span_ratio * self.I_max
        return np.linspace(-span, span, self.grid_points)

    def check_monotone(self, refine: int = 8) -> float:
        """Smallest eigenvalue of the inductance matrix over the grid's span (a grid `refine`
        times finer), H; raises ValueError if it is not positive (a non-monotone map)."""
        span = self.grid_span_ratio * self.I_max
        ax = np.linspace(-span, span, refine * (self.grid_points - 1) + 1)
        I_d, I_q = np.meshgrid(ax, ax, indexing="ij")
        a, b, c = self.inductances(I_d, I_q)
        lam_min = 0.5 * (a + c) - np.sqrt(0.25 * (a - c) ** 2 + b**2)
        k = np.unravel_index(np.argmin(lam_min), lam_min.shape)
        if not lam_min[k] > 0:
            raise ValueError(f"{self}: the inductance matrix is not positive definite at i_d = {I_d[k]:.1f} A, "
                             f"i_q = {I_q[k]:.1f} A (smallest eigenvalue {lam_min[k]:.3e} H): not a monotone map; "
                             "lower the cross-saturation or raise the saturation currents")
        return float(lam_min[k])

    def metadata(self) -> dict:
        """The contract's '# key: value' lines: what the FMUs' parameters and the scenarios read."""
        md = dict(pole_pairs=self.pole_pairs, R_s_ohm=self.R_s, T_winding_ref_K=T_REF, alpha_cu_per_K=ALPHA_CU,
                  T_magnet_ref_K=T_REF, k_psi_T_per_K=K_PSI_T, I_max_A=self.I_max, u_dc_V=U_DC, k_u=K_U,
                  w_m_max_rad_s=W_M_MAX, psi_m_Wb=self.psi_m)
        md.update(sat_I_s_A=self.I_s, sat_I_ds_A="none" if self.I_ds_ratio is None else self.I_ds_ratio * self.I_max,
                  sat_cross=self.cross, sat_L_d_H=self.L_d, sat_L_q_H=self.L_q)
        return md

    def describe(self) -> str:
        d = "none" if self.I_ds_ratio is None else f"I_ds = {self.I_ds_ratio:g} I_max"
        return (f"strongly saturating IPMSM: I_s = {self.I_s_ratio:g} I_max, d-axis saturation {d}, "
                f"cross-saturation {self.cross:.0%}")


def make_map(m: SaturatingMachine) -> FluxMap:
    """The machine's flux map on its grid (checked monotone)."""
    m.check_monotone()
    ax = m.axis()
    I_d, I_q = np.meshgrid(ax, ax, indexing="ij")
    psi_d, psi_q = m.flux(I_d, I_q)
    return FluxMap(ax, ax.copy(), psi_d, psi_q, m.metadata())


def write_map(path: str | Path, m: SaturatingMachine) -> FluxMap:
    """Generate and write the contract CSV; returns the map as written."""
    fmap = make_map(m)
    header = (f"{m.describe()} (synthetic test map, not a real motor).\n"
              f"Generated by 'python -m tools.saturating_map' with {asdict(m)}.\n"
              "Co-energy W = psi_m i_d + L_d F(i_d) + (1 - k_x tanh(i_d/I_x)) L_q I_s^2 (sqrt(1 + (i_q/I_s)^2) - 1),\n"
              "psi = grad W: reciprocal by construction (see tools/saturating_map.py).")
    write_flux_map(path, fmap, header)
    return fmap


def written(I_s_ratio: float, I_ds_ratio: float | None, cross: float, folder: str | Path):
    """The machine and the path of its map written in folder (the tests' fixtures)."""
    m = SaturatingMachine(I_s_ratio=I_s_ratio, I_ds_ratio=I_ds_ratio, cross=cross)
    path = Path(folder) / "map.csv"
    write_map(path, m)
    return m, path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.saturating_map", description=__doc__.split("\n\n")[0])
    ap.add_argument("--I-s-ratio", type=float, default=0.3, help="q-axis saturation current / I_max (0.2 ... 1)")
    ap.add_argument("--I-ds-ratio", type=float, default=None, help="d-axis saturation current for i_d > 0 / I_max")
    ap.add_argument("--cross", type=float, default=0.0, help=f"cross-saturation k_x (0 ... {CROSS_MAX})")
    ap.add_argument("--points", type=int, default=GRID_POINTS, help="grid points per axis")
    ap.add_argument("--span", type=float, default=GRID_SPAN_RATIO, help="grid half-span / I_max")
    ap.add_argument("--I-max", type=float, default=I_MAX, help="peak current limit, A")
    ap.add_argument("--out", type=Path, required=True, help="CSV to write")
    a = ap.parse_args(argv)
    try:
        m = SaturatingMachine(a.I_s_ratio, a.I_ds_ratio, a.cross, I_max=a.I_max, grid_points=a.points,
                              grid_span_ratio=a.span)
        write_map(a.out, m)
    except ValueError as e:
        ap.exit(2, f"error: {e}\n")
    print(f"{a.out}: {m.describe()}, {m.grid_points} x {m.grid_points} points over +-{m.grid_span_ratio:g} I_max")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
