"""The least-loss quartic of docs/spec/MATH.md ("Least-loss control on a linear machine: a
quartic"), derived with sympy from the Lagrangian and checked against the formulas written there,
symbolically; then numerically against a search along the shaft-torque curve.

    python tools/least_loss_quartic.py      # prints what it checked; exits 1 on a mismatch
"""
from __future__ import annotations

import math
import sys

import numpy as np
import sympy as sp


def derive():
    """The step's Lagrange system solved for i(lambda), and h(i(lambda)) D^2 - T D^2 expanded."""
    i_d, i_q, lam = sp.symbols("i_d i_q lambda", real=True)
    A, e, K, kappa, kT, psi_m, L_d, L_q, T = sp.symbols("A e K kappa k_T psi_m L_d L_q T", real=True)
    psi_d, psi_q = psi_m + L_d * i_d, L_q * i_q
    Q = A * (i_d**2 + i_q**2) + e * K * (psi_d**2 + psi_q**2)
    h = kT * (psi_m * i_q + (L_d - L_q) * i_d * i_q) - kappa * (psi_d**2 + psi_q**2)
    # grad Q = lambda grad h: linear in (i_d, i_q)
    eqs = [sp.diff(Q, v) - lam * sp.diff(h, v) for v in (i_d, i_q)]
    M, r = sp.linear_eq_to_matrix(eqs, [i_d, i_q])
    D = sp.expand(M.det())
    N = (M.adjugate() * r).applyfunc(sp.expand)
    # h(N/D) D^2 = T D^2
    hN = h.subs({i_d: N[0] / D, i_q: N[1] / D}, simultaneous=True)
    quartic = sp.expand(sp.cancel(hN * D**2) - T * D**2)
    symbols = dict(lam=lam, A=A, e=e, K=K, kappa=kappa, kT=kT, psi_m=psi_m, L_d=L_d, L_q=L_q, T=T)
    return quartic, D, N, symbols


def documented(s):
    """The formulas as MATH.md writes them (and control/least_loss_linear.cpp computes them)."""
    lam, A, e, K, kappa, kT = s["lam"], s["A"], s["e"], s["K"], s["kappa"], s["kT"]
    psi_m, L_d, L_q, T = s["psi_m"], s["L_d"], s["L_q"], s["T"]
    dL = L_d - L_q
    m11 = 2 * A + 2 * (e * K + lam * kappa) * L_d**2
    m22 = 2 * A + 2 * (e * K + lam * kappa) * L_q**2
    off = -lam * kT * dL
    r_d, r_q = -2 * (e * K + lam * kappa) * L_d * psi_m, lam * kT * psi_m
    D = m11 * m22 - off**2
    N_d, N_q = m22 * r_d - off * r_q, m11 * r_q - off * r_d
    q = kT * (psi_m * N_q * D + dL * N_d * N_q) - kappa * ((psi_m * D + L_d * N_d) ** 2 + (L_q * N_q) ** 2) - T * D**2
    return sp.expand(q), sp.expand(D), (sp.expand(N_d), sp.expand(N_q))


def check_symbolic() -> list[str]:
    quartic, D, N, s = derive()
    q_doc, D_doc, N_doc = documented(s)
    lam = s["lam"]
    out = []
    deg = sp.Poly(quartic, lam).degree()
    out.append(f"degree in lambda of h(i(lambda)) D^2 - T D^2: {deg}")
    if deg != 4:
        raise AssertionError(f"expected a quartic, got degree {deg}")
    # the documented D, N agree with the derived ones up to one common factor (the sign convention
    # of moving lambda grad h to the left side): the quartic up to its square
    ratio = sp.simplify(D_doc / D)
    if not ratio.is_number:
        raise AssertionError(f"D differs by a non-constant factor {ratio}")
    for n_doc, n in zip(N_doc, N):
        if sp.simplify(n_doc - ratio * n) != 0:
            raise AssertionError("N(lambda) differs from the derivation")
    if sp.simplify(q_doc - ratio**2 * quartic) != 0:
        raise AssertionError("the documented quartic differs from the derivation")
    out.append(f"documented D, N and quartic equal the derivation (common factor {ratio})")
    return out


def check_numeric(rng=np.random.default_rng(7), cases=20) -> list[str]:
    """Majorise-minimise with the documented quartic (numpy roots) against a search along the
    curve (rays, the conic's crossing in closed form, golden section in the angle)."""
    _, _, _, s = derive()
    q_doc, D_doc, N_doc = documented(s)
    args = [s[k] for k in ("lam", "A", "e", "K", "kappa", "kT", "psi_m", "L_d", "L_q", "T")]
    coeffs = sp.lambdify(args[1:], sp.Poly(q_doc, s["lam"]).all_coeffs())
    point = sp.lambdify(args, [N_doc[0] / D_doc, N_doc[1] / D_doc])
    worst = 0.0
    for _ in range(cases):
        kT, psi_m = 6.0, 0.078
        L_d, L_q = 2e-4 * rng.uniform(0.5, 1.5), 6e-4 * rng.uniform(0.5, 1.5)
        w = rng.uniform(100, 1200) * rng.choice([-1, 1])
        K = rng.uniform(1e2, 3e4)
        a, b, e = 0.019, 3.2, 1 - 0.1 / 355
        T = rng.uniform(-150, 150)
        J = lambda i_d, i_q: a * (i_d**2 + i_q**2) + b * math.hypot(i_d, i_q) + e * K * (  # noqa: E731
            (psi_m + L_d * i_d) ** 2 + (L_q * i_q) ** 2)
        rho = 50.0
        for _ in range(300):
            A = a + b / (2 * rho)
            roots = np.roots(coeffs(A, e, K, K / w, kT, psi_m, L_d, L_q, T))
            best = None
            for lam in roots[abs(roots.imag) < 1e-9 * (1 + abs(roots.real))].real:
                i_d, i_q = point(lam, A, e, K, K / w, kT, psi_m, L_d, L_q, T)
                Q = A * (i_d**2 + i_q**2) + e * K * ((psi_m + L_d * i_d) ** 2 + (L_q * i_q) ** 2)
                if best is None or Q < best[0]:
                    best = (Q, i_d, i_q)
            rho_new = math.hypot(best[1], best[2])
            if abs(rho_new - rho) <= 1e-14 * rho_new:
                break
            rho = rho_new
        J_mm = J(best[1], best[2])

        def on_ray(phi):
            c, sn = math.cos(phi), math.sin(phi)
            A2 = kT * (L_d - L_q) * c * sn - K / w * (L_d**2 * c * c + L_q**2 * sn * sn)
            A1 = kT * psi_m * sn - K / w * 2 * psi_m * L_d * c
            A0 = -K / w * psi_m**2 - T
            rs = [x.real for x in np.roots([A2, A1, A0]) if abs(x.imag) < 1e-12 and x.real > 0]
            return J(min(rs) * c, min(rs) * sn) if rs else math.inf

        phis = np.linspace(-math.pi, math.pi, 20000, endpoint=False)
        vals = np.array([on_ray(p) for p in phis])
        k = int(np.argmin(vals))
        lo, hi = phis[k] - 2 * math.pi / 20000, phis[k] + 2 * math.pi / 20000
        for _ in range(200):
            m1, m2 = lo + 0.381966 * (hi - lo), hi - 0.381966 * (hi - lo)
            if on_ray(m1) < on_ray(m2):
                hi = m2
            else:
                lo = m1
        J_bf = min(vals[k], on_ray(0.5 * (lo + hi)))
        rel = (J_mm - J_bf) / J_bf
        worst = max(worst, abs(rel))
        if abs(rel) > 1e-9:
            raise AssertionError(f"quartic {J_mm} W against the search's {J_bf} W ({rel:.2e})")
    return [f"{cases} random linear machines: the quartic's least loss equals the search along the curve "
            f"to {worst:.1e} (relative)"]


def main() -> int:
    try:
        for line in check_symbolic() + check_numeric():
            print(line)
    except AssertionError as e:
        print(f"least_loss_quartic: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
