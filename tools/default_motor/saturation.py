"""Energy-consistent saturation model of the default IPMSM: flux linkages psi(i_d, i_q).

Model (amplitude-invariant dq, peak values, PM flux on +d)
---------------------------------------------------------
The iron is described by the algebraic "current from flux" model of Hinkkanen et al. [Hin2017],
which derives the currents from a magnetic energy W(psi_d, psi_q):

    W(psi) = a_d0/2 psi_d^2 + a_dd/(S+2) |psi_d|^(S+2)
           + a_q0/2 psi_q^2 + a_qq/(T+2) |psi_q|^(T+2)
           + a_dq/((U+2)(V+2)) |psi_d|^(U+2) |psi_q|^(V+2)

The permanent magnet is an ideal MMF source on the d axis: an equivalent d-axis current i_f
(the magnet seen as a coil carrying a constant current, as in PM-assisted SyRM models; see
[Lel2024] for a refined version with a saturable bridge). The stator currents are therefore

    i_d = dW/dpsi_d - i_f,        i_q = dW/dpsi_q.

Because the currents are the gradient of one scalar function, the incremental inverse-inductance
matrix d i / d psi is the Hessian of W (symmetric), and so is its inverse, the incremental
inductance matrix d psi / d i: the map is reciprocal, dpsi_d/di_q = dpsi_q/di_d, exactly by
construction. Equivalently psi = grad W'(i) with the co-energy W'(i) = max_psi [psi . (i + i_f e_d)
- W(psi)] (the Legendre transform), so the torque T = 1.5 p (psi_d i_q - psi_q i_d) is consistent
with the energy balance.

Why the magnet is a current and not a flux offset: with the usual PMSM variant of [Hin2017]
(W evaluated at psi_d - psi_f), psi_d at i_d = 0 would not depend on i_q at all. Here, at
i_d = 0 the d-axis balance reads (a_d0 + a_dd |psi_d|^S + a_dq/(V+2) |psi_d|^U |psi_q|^(V+2)) psi_d
= i_f, so a growing |psi_q| lowers psi_d: the PM flux linkage drops with load (cross-saturation of
the d-axis/magnet path by the q-axis current), as measured on real IPMSMs.

Smoothness: i(psi) is C2 when S > 1, T > 1, U = 0 or U > 1, and V >= 0; where the Hessian is
positive definite (checked over the map's range by the tests) psi(i) is then C2 as well, and
psi_d increases with i_d, psi_q with i_q. With U = 2 and V = 0 the cross term is a polynomial.

Sources
-------
[Hin2017] M. Hinkkanen, P. Pescetto, E. Moelsae, S. E. Saarakkala, G. Pellegrino, R. Bojoi,
  "Sensorless self-commissioning of synchronous reluctance motors at standstill without rotor
  locking," IEEE Trans. Ind. Appl. 53(3), 2017, doi:10.1109/TIA.2016.2644624.
[Lel2024] F. Lelli, M. Hinkkanen, F. Giulii Capponi, "A saturation model based on a simplified
  equivalent magnetic circuit for permanent magnet machines," Proc. ICEM 2024,
  doi:10.1109/ICEM60801.2024.10700403.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SaturationParams:
    """Coefficients of the model above. Fluxes in Wb, currents in A (peak)."""

    # d axis (PM axis): small unsaturated inductance because the flux path crosses the magnets.
    a_d0: float = 4500.0  # A/Wb = 1/L_d0: L_d0 = 0.222 mH, mid of 0.15-0.3 mH for ~100 kW 8-pole IPMSMs
    a_dd: float = 3.0e6  # A/Wb^5: d-axis self-saturation (teeth, magnet bridges): L_d at i = 0 is 11 % below L_d0
    S: float = 4.0  # d-axis self-saturation exponent (Hin2017 uses 5 for a SyRM; 4 keeps i(psi) polynomial)
    # q axis (reluctance axis): large unsaturated inductance, saturating strongly with load.
    a_q0: float = 1650.0  # A/Wb = 1/L_q0: L_q0 = 0.606 mH (brief: 0.4-0.8 mH; saliency L_q0/L_d0 = 2.7)
    a_qq: float = 6.0e4  # A/Wb^3: q-axis self-saturation; secant L_q at i_q = 500 A is 52 % of L_q0
    T: float = 2.0  # q-axis self-saturation exponent (> 1 for C2; Hin2017 fits 1 for a SyRM)
    # cross-saturation (shared teeth and yoke): lowers psi_d with |i_q| and psi_q with |psi_d|.
    a_dq: float = 1.2e7  # A/Wb^5: PM flux linkage 12 % lower at i_q = 500 A, i_d = 0
    U: float = 2.0  # first cross exponent (0 or > 1 for C2)
    V: float = 0.0  # second cross exponent (>= 0)
    # permanent magnet as an equivalent d-axis current (MMF source)
    # A: psi_d(-i_f, 0) = 0, i.e. the characteristic current, 0.72 I_max (field weakening to any speed)
    i_f: float = 360.0

    def __post_init__(self) -> None:
        if min(self.a_d0, self.a_q0) <= 0 or min(self.a_dd, self.a_qq, self.a_dq) < 0:
            raise ValueError("a_d0, a_q0 must be positive and a_dd, a_qq, a_dq non-negative")
        if not (self.S > 1 and self.T > 1 and (self.U == 0 or self.U > 1) and self.V >= 0):
            raise ValueError("exponents must satisfy S > 1, T > 1, U = 0 or U > 1, V >= 0 (C2 model)")


DEFAULT = SaturationParams()


def energy(psi_d, psi_q, par: SaturationParams = DEFAULT):
    """Magnetic energy W(psi) of the iron (J), without the magnet's i_f psi_d term."""
    ad, aq = np.abs(psi_d), np.abs(psi_q)
    return (
        0.5 * par.a_d0 * ad**2
        + par.a_dd / (par.S + 2) * ad ** (par.S + 2)
        + 0.5 * par.a_q0 * aq**2
        + par.a_qq / (par.T + 2) * aq ** (par.T + 2)
        + par.a_dq / ((par.U + 2) * (par.V + 2)) * ad ** (par.U + 2) * aq ** (par.V + 2)
    )


def _grad(psi_d, psi_q, par):
    """dW/dpsi: the currents of the iron circuit, i_d + i_f and i_q."""
    ad, aq = np.abs(psi_d), np.abs(psi_q)
    g_d = par.a_d0 + par.a_dd * ad**par.S + par.a_dq / (par.V + 2) * ad**par.U * aq ** (par.V + 2)
    g_q = par.a_q0 + par.a_qq * aq**par.T + par.a_dq / (par.U + 2) * ad ** (par.U + 2) * aq**par.V
    return g_d * psi_d, g_q * psi_q


def flux_hessian(psi_d, psi_q, par: SaturationParams = DEFAULT):
    """Hessian of W = incremental inverse inductances d i / d psi (A/Wb): (H_dd, H_dq, H_qq)."""
    ad, aq = np.abs(psi_d), np.abs(psi_q)
    h_dd = (
        par.a_d0
        + (par.S + 1) * par.a_dd * ad**par.S
        + par.a_dq * (par.U + 1) / (par.V + 2) * ad**par.U * aq ** (par.V + 2)
    )
    h_qq = (
        par.a_q0
        + (par.T + 1) * par.a_qq * aq**par.T
        + par.a_dq * (par.V + 1) / (par.U + 2) * ad ** (par.U + 2) * aq**par.V
    )
    h_dq = par.a_dq * ad**par.U * psi_d * aq**par.V * psi_q
    return h_dd, h_dq, h_qq


def current_from_flux(psi_d, psi_q, par: SaturationParams = DEFAULT):
    """Stator currents (A) at the flux linkages psi_d, psi_q (Wb): the model's explicit direction."""
    x_d, x_q = _grad(np.asarray(psi_d, float), np.asarray(psi_q, float), par)
    return x_d - par.i_f, x_q


def flux_from_current(i_d, i_q, par: SaturationParams = DEFAULT, tol_A: float = 1e-9):
    """Flux linkages (Wb) at the currents i_d, i_q (A), arrays of any broadcastable shapes.

    Solves grad W(psi) = (i_d + i_f, i_q) by Newton's method on the strictly convex function
    Phi(psi) = W(psi) - psi . (i_d + i_f, i_q), with backtracking while far from the solution.
    The solution is odd in i_q exactly (W is even in psi_q): solved for |i_q|, then signed.
    Raises RuntimeError if some point does not converge to tol_A.
    """
    i_d, i_q = np.broadcast_arrays(np.asarray(i_d, float), np.asarray(i_q, float))
    x_d = i_d + par.i_f
    x_q = np.abs(i_q)
    # start from the unsaturated linear solution, clipped to a plausible flux range
    psi_d = np.clip(x_d / par.a_d0, -0.3, 0.3)
    psi_q = np.clip(x_q / par.a_q0, 0.0, 0.5)

    def phi(pd, pq):
        return energy(pd, pq, par) - x_d * pd - x_q * pq

    for _ in range(200):
        g_d, g_q = _grad(psi_d, psi_q, par)
        r_d, r_q = g_d - x_d, g_q - x_q
        if np.max(np.abs(r_d), initial=0.0) < tol_A and np.max(np.abs(r_q), initial=0.0) < tol_A:
            break
        h_dd, h_dq, h_qq = flux_hessian(psi_d, psi_q, par)
        det = h_dd * h_qq - h_dq**2
        s_d = (h_qq * r_d - h_dq * r_q) / det
        s_q = (h_dd * r_q - h_dq * r_d) / det
        decrement = r_d * s_d + r_q * s_q  # Newton decrement squared, >= 0
        t = np.ones_like(psi_d)
        phi0 = phi(psi_d, psi_q)
        far = decrement > 1e-10  # line search only far from the solution (round-off near it)
        for _ in range(60):
            bad = far & (phi(psi_d - t * s_d, psi_q - t * s_q) > phi0 - 0.25 * t * decrement)
            if not bad.any():
                break
            t = np.where(bad, 0.5 * t, t)
        psi_d = psi_d - t * s_d
        psi_q = psi_q - t * s_q
    else:
        raise RuntimeError("flux_from_current: Newton iteration did not converge")
    return psi_d, np.sign(i_q) * psi_q


def incremental_inductances(i_d, i_q, par: SaturationParams = DEFAULT):
    """Incremental inductances (H) at the currents: (L_dd, L_dq, L_qq), L_dq = L_qd exactly."""
    psi_d, psi_q = flux_from_current(i_d, i_q, par)
    h_dd, h_dq, h_qq = flux_hessian(psi_d, psi_q, par)
    det = h_dd * h_qq - h_dq**2
    return h_qq / det, -h_dq / det, h_dd / det


def coenergy(i_d, i_q, par: SaturationParams = DEFAULT):
    """Co-energy W'(i) = psi . (i_d + i_f, i_q) - W(psi) (J); psi = grad W'."""
    psi_d, psi_q = flux_from_current(i_d, i_q, par)
    return psi_d * (np.asarray(i_d) + par.i_f) + psi_q * np.asarray(i_q) - energy(psi_d, psi_q, par)
