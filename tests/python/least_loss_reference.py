"""Independent reference for the least-loss commands (objective = 1): the drive's loss written here
from the contract's formulas (docs/spec/INTERFACE.md, "Least-loss control"), the map through scipy's
splines (scenarios.maps.flux_map), dense sampling of the current disk then SLSQP from the best
samples. Shares nothing with the C++ solver but the equations and the map's data."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from brute_force import Drive, slsqp, slsqp_constraint


@dataclass(frozen=True)
class LossParams:
    """The iron-loss fit and the inverter (the plant's parameter names and meanings)."""
    fe_k_h: float = 1.06664735685
    fe_alpha: float = 2.0
    fe_k_e: float = 0.00581807649193
    fe_psi_ref: float = 0.0780669432093
    f_sw: float = 10e3
    V_T0: float = 0.70
    r_T: float = 0.60e-3
    V_D0: float = 0.80
    r_D: float = 0.70e-3
    E_on: float = 28e-3
    E_off: float = 42e-3
    E_rec: float = 18e-3
    I_ref: float = 820.0
    V_ref: float = 400.0
    k_v: float = 1.0

    def fmu_parameters(self) -> dict:
        return dict(self.__dict__)


@dataclass
class LossDrive:
    """A drive (brute_force.Drive: map, limits, speed) with its loss model at w_m, u_dc."""
    d: Drive
    w_m: float
    u_dc: float
    loss: LossParams

    def parts(self, i_d, i_q):
        return self.parts_at_flux(i_d, i_q, *self.d.flux(i_d, i_q))

    def parts_at_flux(self, i_d, i_q, psi_d, psi_q):
        """parts() where the flux linkages (with the magnets' shift) are known already."""
        d, L = self.d, self.loss
        T_e = d.torque_at(i_d, i_q, psi_d, psi_q)
        I2 = i_d**2 + i_q**2
        I = np.sqrt(I2)
        P_cu = 1.5 * d.R_s * I2
        f = d.pole_pairs * abs(self.w_m) / (2 * math.pi)
        b = np.hypot(psi_d, psi_q) / L.fe_psi_ref
        P_fe = L.fe_k_h * f * b**L.fe_alpha + L.fe_k_e * f**2 * b**2
        P_ac = T_e * self.w_m + P_cu
        P_inv = ((3 / math.pi) * (L.V_T0 + L.V_D0) * I + 0.75 * (L.r_T + L.r_D) * I2
                 + (L.V_T0 - L.V_D0) * P_ac / self.u_dc
                 + (6 / math.pi) * L.f_sw * (L.E_on + L.E_off + L.E_rec) * (I / L.I_ref)
                 * (self.u_dc / L.V_ref) ** L.k_v)
        T_shaft = T_e - (P_fe / self.w_m if self.w_m != 0 else 0.0)
        return T_shaft, P_cu + P_fe + P_inv

    def shaft(self, i_d, i_q):
        return self.parts(i_d, i_q)[0]

    def total(self, i_d, i_q):
        return self.parts(i_d, i_q)[1]


def _disk(I_max, left_half, n_r=120, n_phi=900):
    r = I_max * np.sqrt(np.linspace(0, 1, n_r))[:, None]
    phi = np.linspace(-np.pi, np.pi, n_phi, endpoint=False)[None, :]
    i_d, i_q = (r * np.cos(phi)).ravel(), (r * np.sin(phi)).ravel()
    if left_half:
        keep = i_d <= 0
        return i_d[keep], i_q[keep]
    return i_d, i_q


#: the disk's samples with the map's flux linkages there, per (map, I_max, half): the magnets'
#: temperature only shifts psi_d, so one evaluation of the splines serves every operating point
_DISKS: dict = {}


def _sampled_disk(L: LossDrive):
    """The disk's currents and, at the drive's magnet shift, its loss, shaft torque and |v|."""
    d = L.d
    key = (id(d.fmap), d.I_max, d.left_half)
    if key not in _DISKS or _DISKS[key][0] is not d.fmap:
        i_d, i_q = _disk(d.I_max, d.left_half)
        _DISKS[key] = (d.fmap, i_d, i_q, *d.fmap.flux(i_d, i_q))
    _, i_d, i_q, psi_d0, psi_q = _DISKS[key]
    psi_d = psi_d0 + d.psi_d_shift
    T, P = L.parts_at_flux(i_d, i_q, psi_d, psi_q)
    V = d.voltage_at(i_d, i_q, psi_d, psi_q)
    return i_d, i_q, T, P, V


def _constraints(L: LossDrive, extra=()):
    d = L.d
    cons = [slsqp_constraint("ineq", lambda x: 1.0 - x[0] ** 2 - x[1] ** 2),
            slsqp_constraint("ineq", lambda x: 1.0 - (d.voltage(x[0] * d.I_max, x[1] * d.I_max) / d.V_max) ** 2)]
    if d.left_half:
        cons.append(slsqp_constraint("ineq", lambda x: -x[0]))
    return cons + list(extra)


def _feasible(L: LossDrive, i_d, i_q, rel=1e-7):
    d = L.d
    return (math.hypot(i_d, i_q) <= d.I_max * (1 + rel) and d.voltage(i_d, i_q) <= d.V_max * (1 + rel)
            and (not d.left_half or i_d <= rel * d.I_max))


#: starts of SLSQP: the best samples, each at least this far (of I_max) from the ones taken, so
#: that each starts on its own stretch of the curve (several disk samples lie on one stretch)
START_APART = 0.02
N_STARTS = 4


def _starts(L: LossDrive, i_d, i_q, order) -> list[np.ndarray]:
    """Up to N_STARTS of the samples in `order` (best first), START_APART I_max apart."""
    taken: list[np.ndarray] = []
    for k in order:
        x = np.array([i_d[k], i_q[k]])
        if all(np.hypot(*(x - y)) >= START_APART * L.d.I_max for y in taken):
            taken.append(x)
            if len(taken) == N_STARTS:
                break
    return taken


def max_shaft_torque(L: LossDrive, sign: float) -> float:
    """The largest sign * T_shaft within both limits."""
    d = L.d
    i_d, i_q, T_shaft, _, V = _sampled_disk(L)
    ok = V <= d.V_max
    if not ok.any():
        return 0.0
    T = np.where(ok, sign * T_shaft, -np.inf)
    scale = max(float(np.max(np.abs(T[ok]))), 1e-9)
    best = float(np.max(T))
    for x in _starts(L, i_d, i_q, np.argsort(T)[::-1][:np.count_nonzero(ok)]):
        x0 = x / d.I_max
        r = slsqp(lambda x: -sign * L.shaft(x[0] * d.I_max, x[1] * d.I_max) / scale, x0, _constraints(L))
        if _feasible(L, *(r.x * d.I_max)):
            best = max(best, float(sign * L.shaft(*(r.x * d.I_max))))
    return best


def least_loss(L: LossDrive, T_target: float, T_scale: float) -> float:
    """The least total loss with T_shaft = T_target within both limits (inf if none found)."""
    d = L.d
    i_d, i_q, T, P, V = _sampled_disk(L)
    ok = (V <= d.V_max) & (np.abs(T - T_target) <= 0.03 * T_scale)
    P = np.where(ok, P, np.inf)
    starts = _starts(L, i_d, i_q, np.argsort(P)[:np.count_nonzero(ok)])
    P_scale = float(np.min(P)) if np.isfinite(np.min(P)) else 1.0
    eq = slsqp_constraint("eq", lambda x: (L.shaft(x[0] * d.I_max, x[1] * d.I_max) - T_target) / T_scale)
    best = math.inf
    for s in starts:
        r = slsqp(lambda x: L.total(x[0] * d.I_max, x[1] * d.I_max) / P_scale, s / d.I_max, _constraints(L, [eq]),
                  maxiter=400)
        x = r.x * d.I_max
        if _feasible(L, *x) and abs(L.shaft(*x) - T_target) <= 1e-7 * T_scale:
            best = min(best, float(L.total(*x)))
    return best
