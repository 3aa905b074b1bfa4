"""Independent reference for the optimal current commands: dense sampling of the feasible set,
then scipy's SLSQP from the best samples. Shares nothing with the C++ solver but the equations
(MATH.md conventions) and the flux-map data (interpolated here by scipy's own splines)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from scenarios.maps.flux_map import FluxMap

#: how many scalar points Drive.flux keeps (a finite-difference gradient in 2-D takes 3)
RECENT_POINTS = 8


@dataclass
class Drive:
    fmap: FluxMap
    pole_pairs: int
    R_s: float  # Ohm
    I_max: float  # A
    V_max: float  # V
    omega: float  # electrical rad/s
    psi_d_shift: float = 0.0  # magnet temperature
    # Search only i_d <= 0: a magnet-free machine's optima tie in mirror pairs (i, -i), and the
    # controller's convention is the branch i_d <= 0 (docs/controller.md).
    left_half: bool = False
    #: the flux linkages at the last few scalar currents: SLSQP evaluates the torque, the voltage
    #: (and the loss) at the same point, and their finite differences at the same neighbours
    _recent: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def flux(self, i_d, i_q):
        """fmap.flux at the magnets' shift; a scalar point evaluated once (the same numbers)."""
        if np.ndim(i_d) or np.ndim(i_q):
            return self.fmap.flux(i_d, i_q, self.psi_d_shift)
        # the signs too: -0.0 == 0.0 as a key, and the spline need not give the same bits at both
        key = (float(i_d), float(i_q), math.copysign(1.0, i_d), math.copysign(1.0, i_q))
        found = self._recent.get(key)
        if found is None:
            if len(self._recent) >= RECENT_POINTS:
                self._recent.clear()
            found = self._recent[key] = self.fmap.flux(i_d, i_q, self.psi_d_shift)
        return found

    def torque(self, i_d, i_q):
        return self.torque_at(i_d, i_q, *self.flux(i_d, i_q))

    def voltage(self, i_d, i_q):
        return self.voltage_at(i_d, i_q, *self.flux(i_d, i_q))

    def torque_at(self, i_d, i_q, psi_d, psi_q):
        """torque() where the flux linkages (with the magnets' shift) are known already."""
        return 1.5 * self.pole_pairs * (psi_d * i_q - psi_q * i_d)

    def voltage_at(self, i_d, i_q, psi_d, psi_q):
        """voltage() where the flux linkages (with the magnets' shift) are known already."""
        return np.hypot(self.R_s * i_d - self.omega * psi_q, self.R_s * i_q + self.omega * psi_d)


def _disk(I_max, n_r=90, n_phi=720):
    r = I_max * np.sqrt(np.linspace(0, 1, n_r))[:, None]
    phi = np.linspace(-np.pi, np.pi, n_phi, endpoint=False)[None, :]
    return (r * np.cos(phi)).ravel(), (r * np.sin(phi)).ravel()


#: SLSQP's finite-difference step (scipy.optimize.minimize's default `eps` for it)
FD_STEP = float(np.sqrt(np.finfo(float).eps))


def forward_difference(fun):
    """fun's gradient as SLSQP computes it when given none (scipy's approx_derivative, 2-point,
    absolute step FD_STEP: the same points, the same numbers; x stays far below 1/FD_STEP),
    without approx_derivative's set-up on every call, which took most of the brute force's time."""
    def gradient(x):
        f0 = float(fun(x))
        g = np.empty(len(x))
        for i in range(len(x)):
            x1 = x.copy()
            x1[i] = x[i] + FD_STEP
            g[i] = (float(fun(x1)) - f0) / ((x[i] + FD_STEP) - x[i])
        return g
    return gradient


def slsqp_constraint(kind: str, fun) -> dict:
    """A constraint for SLSQP, its gradient by forward_difference."""
    return {"type": kind, "fun": fun, "jac": forward_difference(fun)}


def slsqp(objective, x0, constraints, maxiter: int = 300):
    """scipy's SLSQP to ftol 1e-15, the objective's gradient by forward_difference."""
    return minimize(objective, x0, jac=forward_difference(objective), method="SLSQP", constraints=constraints,
                    options={"ftol": 1e-15, "maxiter": maxiter})


def _constraints(d: Drive, extra=()):
    I, V = d.I_max, d.V_max
    cons = [
        slsqp_constraint("ineq", lambda x: 1.0 - x[0] ** 2 - x[1] ** 2),
        slsqp_constraint("ineq", lambda x: 1.0 - (d.voltage(x[0] * I, x[1] * I) / V) ** 2),
    ]
    if d.left_half:
        cons.append(slsqp_constraint("ineq", lambda x: -x[0]))
    return cons + list(extra)


def _feasible(d: Drive, i_d, i_q, rel=1e-7):
    return (np.hypot(i_d, i_q) <= d.I_max * (1 + rel) and d.voltage(i_d, i_q) <= d.V_max * (1 + rel)
            and (not d.left_half or i_d <= rel * d.I_max))


def _disk_of(d: Drive):
    i_d, i_q = _disk(d.I_max)
    if d.left_half:
        keep = i_d <= 0
        return i_d[keep], i_q[keep]
    return i_d, i_q


#: the disk's samples with the map's flux linkages there, per (map, I_max, half): the magnets'
#: temperature only adds to psi_d, so one evaluation of the splines serves every operating point
_DISKS: dict = {}
#: the maps whose disks are kept (a test module's few; more are evaluated again)
DISKS_KEPT = 8


def _sampled_disk(d: Drive):
    """The disk's currents (_disk_of) and there Drive.torque and Drive.voltage (the same numbers)."""
    key = (id(d.fmap), d.I_max, d.left_half)
    if key not in _DISKS or _DISKS[key][0] is not d.fmap:
        if len(_DISKS) >= DISKS_KEPT:
            _DISKS.clear()
        i_d, i_q = _disk_of(d)
        _DISKS[key] = (d.fmap, i_d, i_q, *d.fmap.flux(i_d, i_q))
    _, i_d, i_q, psi_d0, psi_q = _DISKS[key]
    psi_d = psi_d0 + d.psi_d_shift
    return i_d, i_q, d.torque_at(i_d, i_q, psi_d, psi_q), d.voltage_at(i_d, i_q, psi_d, psi_q)


def max_torque(d: Drive, sign: float) -> tuple[float, np.ndarray]:
    """Largest sign*T within both limits, and the currents giving it."""
    i_d, i_q, T_disk, V_disk = _sampled_disk(d)
    ok = (V_disk <= d.V_max)
    if not ok.any():
        return 0.0, np.array([np.nan, np.nan])
    T = np.where(ok, sign * T_disk, -np.inf)
    T_scale = max(np.max(T), 1e-9)
    best_T, best_x = -np.inf, None
    for k in np.argsort(T)[-4:]:
        x0 = np.array([i_d[k], i_q[k]]) / d.I_max
        r = slsqp(lambda x: -sign * d.torque(x[0] * d.I_max, x[1] * d.I_max) / T_scale, x0, _constraints(d))
        for x in (r.x, x0):
            if _feasible(d, *(x * d.I_max)):
                Tx = float(sign * d.torque(*(x * d.I_max)))
                if Tx > best_T:
                    best_T, best_x = Tx, x * d.I_max
    return max(best_T, 0.0), best_x


def min_current(d: Drive, T_target: float, T_scale: float) -> tuple[float, np.ndarray]:
    """Least current magnitude giving T_target within both limits, and the currents."""
    i_d, i_q, T, V = _sampled_disk(d)
    ok = (V <= d.V_max) & (np.abs(T - T_target) <= 0.03 * T_scale)
    I = np.where(ok, np.hypot(i_d, i_q), np.inf)
    starts = [np.array([i_d[k], i_q[k]]) for k in np.argsort(I)[:4] if np.isfinite(I[k])]
    if not starts:
        starts = [np.array([0.0, 0.0])]
    eq = slsqp_constraint("eq", lambda x: (d.torque(x[0] * d.I_max, x[1] * d.I_max) - T_target) / T_scale)
    best_I, best_x = np.inf, None
    for s in starts:
        r = slsqp(lambda x: x[0] ** 2 + x[1] ** 2, s / d.I_max, _constraints(d, [eq]))
        x = r.x * d.I_max
        if _feasible(d, *x) and abs(d.torque(*x) - T_target) <= 1e-7 * T_scale:
            if np.hypot(*x) < best_I:
                best_I, best_x = float(np.hypot(*x)), x
    return best_I, best_x


class LevelScan:
    """The least current for many torques at one operating point, by rays: the torque on a polar
    grid (n_r radii x n_rays angles), for each target the first crossing along every ray
    (bisection on the spline), the least radius among the rays within the voltage limit, and
    where the voltage limit cuts the level curve next to it, bisection on the angle. An upper
    bound on the least current, within (curvature x angle step^2) of it: an independent
    reference for dense torque sweeps, where SLSQP per point would take minutes."""

    def __init__(self, d: Drive, sign: float, n_rays: int = 1024, n_r: int = 200):
        lo, hi = (0.5 * np.pi, 1.5 * np.pi) if d.left_half else (-np.pi, np.pi)
        self.d, self.sign = d, sign
        self.theta = np.linspace(lo, hi, n_rays, endpoint=not d.left_half)
        self.r = np.linspace(0.0, d.I_max, n_r)
        R, TH = np.meshgrid(self.r, self.theta, indexing="ij")
        self.T = sign * d.torque(R * np.cos(TH), R * np.sin(TH))  # (n_r, n_rays)

    def _roots(self, T_target: float, theta: np.ndarray, lo: np.ndarray, hi: np.ndarray, n: int = 45):
        c, s = np.cos(theta), np.sin(theta)
        for _ in range(n):
            m = 0.5 * (lo + hi)
            above = self.sign * self.d.torque(m * c, m * s) >= T_target
            hi, lo = np.where(above, m, hi), np.where(above, lo, m)
        return hi

    def least_current(self, T_target: float) -> float:
        """Least |i| with sign*T = T_target (> 0) within both limits; inf if none."""
        d = self.d
        above = self.T >= T_target
        has = above.any(axis=0)
        k = np.argmax(above, axis=0)
        lo = self.r[np.maximum(k - 1, 0)]
        hi = self.r[k]
        r = np.where(has, self._roots(T_target, self.theta, lo, hi), np.inf)
        ok = has & (d.voltage(r * np.cos(self.theta), r * np.sin(self.theta)) <= d.V_max)
        if not ok.any():
            return np.inf
        j = int(np.argmin(np.where(ok, r, np.inf)))
        best = r[j]
        n = len(self.theta)
        for o in (j - 1, j + 1):  # the voltage limit between j and an infeasible neighbour
            if 0 <= o < n and has[o] and not ok[o]:
                a, b = self.theta[j], self.theta[o]
                for _ in range(50):
                    m = 0.5 * (a + b)
                    rm = float(self._roots(T_target, np.array([m]), np.array([0.0]), np.array([d.I_max]), 80)[0])
                    if d.voltage(rm * np.cos(m), rm * np.sin(m)) <= d.V_max:
                        a, best = m, min(best, rm)
                    else:
                        b = m
        return float(best)
