"""The figure of `map show`: eight panels of one machine (see map_show.py for where each comes from)."""
from __future__ import annotations

import numpy as np

from scenarios.core.boundary import write_atomically
from scenarios.maps.flux_map import FluxMap

RPM = 2 * np.pi / 60


def plot_machine(png, fmap: FluxMap, s, env, speeds, mtpa, mismatch, eff_speeds, eff_torques, eta) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    I_max = s.parameters["I_max"]
    p = s.parameters["pole_pairs"]
    I_d, I_q = np.meshgrid(fmap.i_d, fmap.i_q, indexing="ij")
    circle = np.linspace(0, 2 * np.pi, 361)
    cx, cy = I_max * np.cos(circle), I_max * np.sin(circle)
    fig, ax = plt.subplots(2, 4, figsize=(20, 9.5))
    fig.suptitle(f"{s.map_file}: {s.grid}; psi_m = {s.psi_m_Wb:.4g} Wb, p = {p}, I_max = {I_max:g} A, "
                 f"u_dc = {s.u_dc_V:g} V", fontsize=10)

    for a, psi, name in ((ax[0, 0], fmap.psi_d, "psi_d"), (ax[0, 1], fmap.psi_q, "psi_q")):
        cs = a.contourf(I_d, I_q, psi, levels=21, cmap="viridis")
        fig.colorbar(cs, ax=a, label=f"{name} (Wb)")
        a.plot(cx, cy, "w--", lw=0.8)
        a.set(title=f"{name}(i_d, i_q)", xlabel="i_d (A)", ylabel="i_q (A)")

    a = ax[0, 2]  # apparent (solid) and incremental (dashed) inductances along the axes
    def along(axis):  # currents along one axis, inside both the grid and the current limit
        v = np.linspace(max(axis[0], -I_max), min(axis[-1], I_max), 201)
        return v[np.abs(v) > 1e-6 * I_max]

    x, y = along(fmap.i_d), along(fmap.i_q)
    for c, alpha in ((0.0, 1.0), (0.5 * I_max, 0.45)):  # on the axes, and with a cross current
        psi_d, _ = fmap.flux(x, c)
        L_dd, _ = fmap.flux(x, c, dx=1)
        _, psi_q = fmap.flux(-c, y)
        _, L_qq = fmap.flux(-c, y, dy=1)
        psi_d0 = fmap.flux(0.0, c)[0]
        a.plot(x, 1e3 * (psi_d - psi_d0) / x, "C0", alpha=alpha, label=f"L_d apparent, i_q = {c:g} A")
        a.plot(x, 1e3 * L_dd, "C0--", alpha=alpha, label=f"L_dd incremental, i_q = {c:g} A")
        a.plot(y, 1e3 * psi_q / y, "C1", alpha=alpha, label=f"L_q apparent, i_d = {0.0 - c:g} A")
        a.plot(y, 1e3 * L_qq, "C1--", alpha=alpha, label=f"L_qq incremental, i_d = {0.0 - c:g} A")
    a.set(title="inductances along the axes", xlabel="i_d for L_d, i_q for L_q (A)", ylabel="mH")
    a.legend(fontsize=7)

    a = ax[0, 3]
    lim = np.abs(mismatch).max() or 1.0
    cs = a.contourf(I_d, I_q, 1e6 * mismatch, levels=np.linspace(-1e6 * lim, 1e6 * lim, 21), cmap="RdBu_r")
    fig.colorbar(cs, ax=a, label="uH")
    a.plot(cx, cy, "k--", lw=0.8)
    a.plot(*s.reciprocity_at_A, "kx")
    a.set(title=f"reciprocity dpsi_d/di_q - dpsi_q/di_d: max {1e6 * s.reciprocity_max_H:.3g} uH "
                f"({100 * s.reciprocity_rel:.2g} %)", xlabel="i_d (A)", ylabel="i_q (A)")
    a.title.set_fontsize(9)

    a = ax[1, 0]  # current plane: torque contours, MTPA, T_max trajectory, MTPV
    T = 1.5 * p * (fmap.psi_d * I_q - fmap.psi_q * I_d)
    cs = a.contour(I_d, I_q, T, levels=np.linspace(-s.T_peak_Nm, s.T_peak_Nm, 17), cmap="coolwarm", linewidths=0.7)
    a.clabel(cs, fontsize=6, fmt="%.0f")
    a.plot(cx, cy, "k--", lw=0.8, label="current limit")
    a.plot(mtpa[:, 0], mtpa[:, 1], "g.-", label="MTPA")
    a.plot(env[:, 1], env[:, 2], "m.", ms=3, label="T_max over speed")
    mtpv = env[:, 3] == 4
    if mtpv.any():
        a.plot(env[mtpv, 1], env[mtpv, 2], "r.-", label="MTPV (region 4)")
    a.set(title="current plane: MTPA, MTPV (controller FMU)", xlabel="i_d (A)", ylabel="i_q (A)", aspect="equal",
          xlim=(fmap.i_d[0], fmap.i_d[-1]), ylim=(min(0, mtpa[:, 1].min()) - 0.05 * I_max, 1.1 * I_max))
    a.legend(fontsize=7)

    a = ax[1, 1]
    a.plot(speeds / RPM, env[:, 0], "b", label="T_max")
    a.axvline(s.w_base_rad_s / RPM, color="gray", ls=":", label="base speed")
    a.set(title=f"torque-speed envelope at u_dc = {s.u_dc_V:g} V", xlabel="speed (r/min)", ylabel="T_max (N m)")
    b = a.twinx()
    b.plot(speeds / RPM, env[:, 0] * speeds / 1e3, "r", label="power")
    b.set_ylabel("P (kW)")
    a.legend(loc="lower left", fontsize=7)

    a = ax[1, 2]
    W, Tq = np.meshgrid(eff_speeds / RPM, eff_torques, indexing="ij")
    if np.isfinite(eta).any():
        lo = max(0.5, np.nanmin(eta))
        top = 100 * np.nanmax(eta)  # 1 % steps where drives differ, coarser below
        levels = np.unique(np.r_[100 * lo, [60, 70, 80, 85, 88], np.arange(90, 100, 1.0), top])
        levels = levels[(levels >= 100 * lo) & (levels <= top)]
        if len(levels) < 2:  # (nearly) one efficiency everywhere: two levels around it
            levels = np.array([100 * np.nanmin(eta) - 0.5, top + 0.5])
        cs = a.contourf(W, Tq, 100 * eta, levels=levels, cmap="jet")
        fig.colorbar(cs, ax=a, label="efficiency (%)")
    a.plot(speeds / RPM, env[:, 0], "k")
    a.set(title="efficiency P_mech / P_dc, motor + inverter (IpmsmDrive FMU)", xlabel="speed (r/min)",
          ylabel="torque (N m)", ylim=(0, 1.05 * s.T_peak_Nm))
    a.title.set_fontsize(9)

    a = ax[1, 3]  # flux curves: psi_d(i_d) at several i_q, psi_q(i_q) at several i_d
    for frac, alpha in ((0.0, 1.0), (0.5, 0.6), (1.0, 0.3)):
        psi_d, _ = fmap.flux(x, frac * I_max)
        _, psi_q = fmap.flux(-frac * I_max, y)
        a.plot(x, psi_d, "C0", alpha=alpha, label=f"psi_d(i_d, i_q = {frac * I_max:g} A)")
        a.plot(y, psi_q, "C1", alpha=alpha, label=f"psi_q(i_d = {0.0 - frac * I_max:g} A, i_q)")
    a.set(title="flux linkage curves (cross-saturation)", xlabel="i_d for psi_d, i_q for psi_q (A)", ylabel="Wb")
    a.legend(fontsize=7)

    fig.tight_layout()
    write_atomically(png, lambda p: fig.savefig(p, format="png", dpi=90))
    plt.close(fig)
