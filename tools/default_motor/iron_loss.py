"""Iron loss of the default IPMSM, in the seed paper's form (13).

    P_fe = k_h f b^alpha + k_e f^2 b^2,      b = |psi| / psi_ref,   |psi| = sqrt(psi_d^2 + psi_q^2)

f = p |w_m| / (2 pi) is the electrical frequency (Hz). The peak flux density in the core is taken
proportional to the stator flux-linkage magnitude: b = B / B_ref, where B_ref is the (effective)
peak flux density reached at |psi| = psi_ref. The first term is hysteresis loss (Steinmetz), the
second classical eddy-current loss; the seed quotes alpha = 1.8-2.2 [seed, Sec. II-C].

Coefficients of the whole machine (W/Hz, W/Hz^2) follow from per-kilogram lamination data, the
core mass, B_ref and a build factor (punching damage, rotational fields, PWM harmonics and rotor
losses, which a two-term model of the sinusoidal-excitation data leaves out; 1.5-2 is usual):

    k_h = k_h,kg * m * k_build * B_ref^alpha,     k_e = k_e,kg * m * k_build * B_ref^2.

As a drag on the rotor the loss is a torque P_fe / w_m (the IpmsmPlant's T_shaft = T_e - that).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class IronLossCoefficients:
    """Machine-level coefficients of P_fe = k_h f b^alpha + k_e f^2 b^2, b = |psi| / psi_ref."""

    k_h: float  # W/Hz: hysteresis coefficient at |psi| = psi_ref
    alpha: float  # Steinmetz exponent of the hysteresis term
    k_e: float  # W/Hz^2: eddy-current coefficient at |psi| = psi_ref
    psi_ref: float  # Wb: flux linkage magnitude at which b = 1 (the no-load flux psi_m)

    def loss(self, psi_mag, f_hz):
        """Iron loss (W) at flux linkage magnitude psi_mag (Wb) and electrical frequency f_hz."""
        b = np.abs(psi_mag) / self.psi_ref
        f = np.abs(f_hz)
        return self.k_h * f * b**self.alpha + self.k_e * f**2 * b**2

    def loss_at_speed(self, psi_mag, w_m, pole_pairs: int):
        """Iron loss (W) at mechanical speed w_m (rad/s)."""
        return self.loss(psi_mag, pole_pairs * np.asarray(w_m) / (2 * math.pi))

    def drag_torque(self, psi_mag, w_m, pole_pairs: int):
        """Iron-loss torque magnitude (N.m), P_fe / |w_m|, written so that w_m -> 0 is finite."""
        b = np.abs(psi_mag) / self.psi_ref
        c = pole_pairs / (2 * math.pi)  # Hz per rad/s
        return self.k_h * c * b**self.alpha + self.k_e * c**2 * np.abs(w_m) * b**2


@dataclass(frozen=True)
class Lamination:
    """Per-kilogram two-term loss data of the electrical steel: p = k_h,kg f B^alpha + k_e,kg f^2 B^2."""

    k_h_W_per_kg_Hz: float  # W/(kg Hz T^alpha)
    k_e_W_per_kg_Hz2: float  # W/(kg Hz^2 T^2)
    alpha: float

    @classmethod
    def fit_two_points(cls, p1, b1, f1, p2, b2, f2, alpha: float) -> Lamination:
        """Fit k_h, k_e to two catalogue points p (W/kg) at (B in T, f in Hz), alpha given."""
        a = np.array([[f1 * b1**alpha, f1**2 * b1**2], [f2 * b2**alpha, f2**2 * b2**2]])
        k_h, k_e = np.linalg.solve(a, [p1, p2])
        return cls(float(k_h), float(k_e), alpha)


# 0.35 mm non-oriented steel of grade M270-35A (EN 10106): 2.70 W/kg at 1.5 T, 50 Hz (the grade's
# guaranteed maximum) and about 24 W/kg at 1.0 T, 400 Hz (typical catalogue value for the grade).
M270_35A = Lamination.fit_two_points(2.70, 1.5, 50.0, 24.0, 1.0, 400.0, alpha=2.0)


def stator_core_mass(d_outer, d_bore, l_stack, slot_fraction, stacking_factor=0.97, density=7650.0):
    """Mass (kg) of a slotted stator core: annulus area less the slots, times stack and density."""
    area = math.pi / 4 * (d_outer**2 - d_bore**2) * (1 - slot_fraction)
    return area * l_stack * stacking_factor * density


def machine_coefficients(lam: Lamination, mass_kg, b_ref_T, build_factor, psi_ref) -> IronLossCoefficients:
    """Whole-machine coefficients from lamination data (see the module docstring)."""
    scale = mass_kg * build_factor
    return IronLossCoefficients(
        k_h=lam.k_h_W_per_kg_Hz * scale * b_ref_T**lam.alpha,
        alpha=lam.alpha,
        k_e=lam.k_e_W_per_kg_Hz2 * scale * b_ref_T**2,
        psi_ref=psi_ref,
    )
