"""Iron-loss coefficients of the contract's model fitted to a FEM tool's iron-loss map.

The model (docs/spec/INTERFACE.md, the plant's fe_* parameters; MATH.md):

    P_fe = fe_k_h f b^fe_alpha + fe_k_e f^2 b^2,   b = |psi| / fe_psi_ref,  f = p w_m / (2 pi)

SyR-e's loss map (motorModel.IronPMLossMap_dq, type 'map') holds the stator and rotor iron
loss per current point at one speed n0 (frequency f0), split into a hysteresis part that
scales as (f / f0)^expH and a classical (eddy) part as (f / f0)^expC (SyR-e's
`MMM_eval_IronLossModel` / `calcLossMapScaled`). With expH = 1 and expC = 2 the model's
frequency dependence is the tool's; the fit is then in |psi| alone: hysteresis by least squares
of P_h = k_h f0 b^alpha (alpha scanned over the contract's [1, 3] in steps of ALPHA_STEP, k_h
linear at each), eddy by linear least squares of P_c = k_e f0^2 b^2. The fit uses the points inside the current limit,
where the drive runs; its error is stated relative to the largest loss there.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the contract's range of fe_alpha (scenarios/drives/description.py, motor.fe_alpha)
ALPHA_RANGE = (1.0, 3.0)
#: the exponent's resolution in the scan
ALPHA_STEP = 0.005


@dataclass(frozen=True)
class IronLossFit:
    k_h: float          # W/Hz at b = 1
    alpha: float
    k_e: float          # W/Hz^2 at b = 1
    psi_ref: float      # Wb
    f0: float           # Hz, the map's frequency
    points: int         # points fitted (inside the current limit)
    max_error_rel: float  # max |fit - map| / max(map), at f0, inside the current limit
    rms_error_rel: float  # RMS of (fit - map) / max(map)

    def loss(self, psi_abs, f):
        b = np.asarray(psi_abs) / self.psi_ref
        return self.k_h * f * b ** self.alpha + self.k_e * f * f * b * b

    def metadata(self) -> dict:
        return {"fe_k_h_W_per_Hz": f"{self.k_h:.12g}", "fe_alpha": f"{self.alpha:.12g}",
                "fe_k_e_W_per_Hz2": f"{self.k_e:.12g}", "fe_psi_ref_Wb": f"{self.psi_ref:.12g}",
                "fe_fit_max_error_rel": f"{self.max_error_rel:.4g}",
                "fe_fit_rms_error_rel": f"{self.rms_error_rel:.4g}"}

    def describe(self) -> str:
        return (f"iron loss fitted to the FEM loss map at {self.f0:g} Hz over {self.points} points inside the current "
                f"limit: fe_k_h {self.k_h:.4g} W/Hz, fe_alpha {self.alpha:.4g}, fe_k_e {self.k_e:.4g} W/Hz^2 at "
                f"fe_psi_ref {self.psi_ref:.4g} Wb; fit error max {100 * self.max_error_rel:.2f} %, RMS "
                f"{100 * self.rms_error_rel:.2f} % of the largest loss there")


def fit(psi_abs: np.ndarray, P_h: np.ndarray, P_c: np.ndarray, f0: float, inside: np.ndarray,
        psi_ref: float | None = None) -> IronLossFit:
    """Fit k_h, alpha (to P_h) and k_e (to P_c), the losses at frequency f0 over flux magnitudes
    psi_abs; `inside` selects the points used. psi_ref None: the largest |psi| inside (so b <= 1)."""
    x, h, c = psi_abs[inside].ravel(), P_h[inside].ravel(), P_c[inside].ravel()
    if psi_ref is None:
        psi_ref = float(x.max())
    b = x / psi_ref
    alpha, k_h, best = 2.0, 0.0, np.inf
    for a in np.arange(ALPHA_RANGE[0], ALPHA_RANGE[1] + ALPHA_STEP / 2, ALPHA_STEP):
        basis = b ** a
        amp = float(basis @ h / max(basis @ basis, 1e-300))
        r = float(np.sum((amp * basis - h) ** 2))
        if r < best:
            alpha, k_h, best = float(a), amp / f0, r
    b2 = b * b
    k_e = float(max(b2 @ c / max(b2 @ b2, 1e-300), 0.0)) / (f0 * f0)
    model = k_h * f0 * b ** alpha + k_e * f0 * f0 * b2
    total = h + c
    scale = max(total.max(), 1e-300)
    err = (model - total) / scale
    return IronLossFit(k_h, alpha, k_e, psi_ref, f0, int(len(x)), float(np.abs(err).max()),
                       float(np.sqrt(np.mean(err * err))))
