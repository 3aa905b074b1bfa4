"""Torque-speed sweep of the IpmsmController FMU: the optimal current trajectories.

For each speed on a grid and each torque command from zero to beyond reach, one controller
step gives the current commands; the result is a table (CSV), a summary (JSON) and a picture
of the trajectories in the i_d-i_q plane with the current circle and voltage ellipses, and the
torque-speed envelope.
"""
from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .constants import T_REFERENCE_K, U_DC_NOMINAL_V
from .flux_map import MotorData, read_flux_map
from .fmu import Fmu
from .progress import Progress

RPM = 2 * math.pi / 60  # rad/s per r/min


@dataclass
class SweepSpec:
    speeds_rpm: tuple = (0, 2000, 3000, 4000, 5000, 6000, 8000, 10000, 12000)
    n_torque: int = 61           # torque commands from 0 to T_overload
    T_overload: float = 320.0    # N.m, beyond the default motor's 285 N.m peak
    u_dc: float = U_DC_NOMINAL_V  # V, nominal 96s NMC pack
    T_magnet: float = T_REFERENCE_K  # K
    method: int = 1
    recursion: int = 2
    step: float = 1e-4           # s


@dataclass(frozen=True)
class SweepSummary:
    """summary.json of a sweep: the spec, the points run, and the torque-speed envelope."""

    spec: dict
    points: int
    wall_s: float
    T_max_Nm_by_speed_rpm: dict   # r/min -> the largest T_max at that speed, N m
    P_max_kW_by_speed_rpm: dict   # r/min -> the power at that torque, kW

    def to_dict(self) -> dict:
        return asdict(self)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)


def run_sweep(controller_fmu: Path, out: Path, spec: SweepSpec | None = None) -> SweepSummary:
    spec = spec if spec is not None else SweepSpec()
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    torques = np.linspace(0.0, spec.T_overload, spec.n_torque)
    t0 = time.perf_counter()
    bar = Progress(len(spec.speeds_rpm) * len(torques), "sweep")
    with Fmu(controller_fmu, method=spec.method, recursion=spec.recursion) as c:
        k = 0
        for n in spec.speeds_rpm:
            for T in torques:
                c.set(T_ref=T, w_m=n * RPM, u_dc=spec.u_dc, T_magnet=spec.T_magnet, i_d=0.0, i_q=0.0)
                c.step(k * spec.step, spec.step)
                i_d, i_q, T_cmd, T_max, region, its = c.get("i_d_ref", "i_q_ref", "T_cmd", "T_max", "region",
                                                            "iterations")
                rows.append(dict(speed_rpm=n, T_ref_Nm=T, T_cmd_Nm=T_cmd, T_max_Nm=T_max, i_d_A=i_d, i_q_A=i_q,
                                 I_A=math.hypot(i_d, i_q), region=region, iterations=its))
                k += 1
                bar.update()
    bar.close()
    wall = time.perf_counter() - t0
    with open(out / "sweep.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    envelope = {n: max(r["T_max_Nm"] for r in rows if r["speed_rpm"] == n) for n in spec.speeds_rpm}
    summary = SweepSummary(spec=asdict(spec), points=len(rows), wall_s=wall, T_max_Nm_by_speed_rpm=envelope,
                           P_max_kW_by_speed_rpm={n: T * n * RPM / 1e3 for n, T in envelope.items()})
    (out / "summary.json").write_text(summary.to_json())
    plot_sweep(rows, spec, controller_fmu, out / "current_trajectories.png")
    return summary


def plot_sweep(rows, spec: SweepSpec, controller_fmu: Path, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from fmpy import extract
    fmap = read_flux_map(Path(extract(str(controller_fmu))) / "resources" / "ev_ipmsm_default.csv")
    motor = MotorData.of(fmap)
    p, R_s, I_max = motor.pole_pairs, motor.R_s, motor.I_max
    V_max = motor.k_u * spec.u_dc / math.sqrt(3)

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(13, 5.6), gridspec_kw=dict(width_ratios=[1.15, 1]))
    th = np.linspace(0, 2 * np.pi, 400)
    ax.plot(I_max * np.cos(th), I_max * np.sin(th), "k--", lw=1, label=f"current limit {I_max:.0f} A")
    # Voltage ellipses (with saturation, from the flux map) and the trajectories, one colour per speed.
    g_d, g_q = np.meshgrid(np.linspace(-560, 100, 331), np.linspace(-20, 560, 291))
    psi_d, psi_q = fmap.flux(g_d, g_q)
    cmap = plt.get_cmap("viridis")
    speeds = [n for n in spec.speeds_rpm if n > 0]
    for j, n in enumerate(spec.speeds_rpm):
        color = cmap(j / max(1, len(spec.speeds_rpm) - 1))
        sel = [r for r in rows if r["speed_rpm"] == n]
        ax.plot([r["i_d_A"] for r in sel], [r["i_q_A"] for r in sel], "-", color=color, lw=2, label=f"{n} r/min")
        if n in speeds:
            w = p * n * RPM
            v = np.hypot(R_s * g_d - w * psi_q, R_s * g_q + w * psi_d)
            ax.contour(g_d, g_q, v, levels=[V_max], colors=[color], linewidths=0.8, linestyles=":")
    ax.set_xlabel("i_d (A)")
    ax.set_ylabel("i_q (A)")
    ax.set_title(f"Optimal current commands, 0 to {spec.T_overload:.0f} N.m\n"
                 f"(dotted: voltage limit at {spec.u_dc:.0f} V)")
    ax.set_aspect("equal")
    ax.set_xlim(-560, 100)
    ax.set_ylim(-20, 560)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")

    n_fine = sorted({r["speed_rpm"] for r in rows})
    T_env = [max(r["T_max_Nm"] for r in rows if r["speed_rpm"] == n) for n in n_fine]
    ax2.plot(n_fine, T_env, "o-", color="C3", label="T_max (controller)")
    ax2b = ax2.twinx()
    ax2b.plot(n_fine, [T * n * RPM / 1e3 for T, n in zip(T_env, n_fine)], "s--", color="C0", label="power")
    ax2.set_xlabel("speed (r/min)")
    ax2.set_ylabel("torque (N.m)", color="C3")
    ax2b.set_ylabel("power (kW)", color="C0")
    ax2.set_title(f"Torque-speed envelope at {spec.u_dc:.0f} V, {I_max:.0f} A")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
