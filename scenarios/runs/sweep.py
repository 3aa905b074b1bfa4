"""Torque-speed sweep of the IpmsmController FMU: the optimal current trajectories.

For each speed on a grid and each torque command from zero to beyond reach, one controller
step gives the current commands; the result is a table (CSV), a summary (JSON) and a picture
of the trajectories in the i_d-i_q plane with the current circle and voltage ellipses, and the
torque-speed envelope.
"""
from __future__ import annotations

import csv
import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from scenarios.core.boundary import strict_json, write_atomically
from scenarios.core.constants import T_REFERENCE_K
from scenarios.core.progress import Progress
from scenarios.cosim.fmu import Fmu
from scenarios.drives.description import DriveDescription, load_drive
from scenarios.maps.flux_map import read_flux_map

RPM = 2 * math.pi / 60  # rad/s per r/min

#: the sweep's torque commands run this far beyond the motor's reach at standstill, so the
#: plot shows where the commands stop growing (the default motor: 285 N m -> 320 N m)
OVERLOAD = 1.12

#: speeds of the sweep below the drive's top speed (which is added), r/min
SPEEDS_RPM = (0, 2000, 3000, 4000, 5000, 6000, 8000, 10000, 12000, 14000, 16000, 18000, 20000)


@dataclass
class SweepSpec:
    """What to sweep: the drive's motor and controller settings (a drive description) at u_dc
    (None: the drive's controller.lut_u_dc), torques 0..T_overload (None: OVERLOAD times the
    reach at standstill, rounded up to 10 N m), speeds in r/min (None: SPEEDS_RPM up to the
    drive's top speed: motor.w_m_max, or the controller FMU's default)."""

    drive: DriveDescription = field(default_factory=load_drive)
    speeds_rpm: tuple | None = None
    n_torque: int = 61           # torque commands from 0 to T_overload
    T_overload: float | None = None  # N.m
    u_dc: float | None = None    # V
    T_magnet: float = T_REFERENCE_K  # K
    method: str = "ferrari"
    recursion: int = 2
    step: float = 1e-4           # s

    def speeds(self) -> tuple:
        """The speeds (r/min); run_sweep fills speeds_rpm in before it starts."""
        if self.speeds_rpm is None:
            raise ValueError("speeds_rpm not set: run_sweep sets it from the drive's top speed")
        return tuple(self.speeds_rpm)

    def to_dict(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k != "drive"}
        return dict(d, drive=self.drive.name, speeds_rpm=list(self.speeds()))


def top_speed(controller_fmu: Path, drive: DriveDescription) -> float:
    """The drive's motor.w_m_max, else the controller FMU's default (rad/s)."""
    if drive.motor.w_m_max is not None:
        return drive.motor.w_m_max
    from scenarios.cosim.fmu import model_description
    md = model_description(Path(controller_fmu))
    return float(next(v.start for v in md.modelVariables if v.name == "w_m_max"))


def reach_at_standstill(controller_fmu: Path, spec: SweepSpec, u_dc: float) -> float:
    """The controller's T_max at w_m = 0 (N m): one step of a fresh instance asked for far too much."""
    with Fmu(controller_fmu, **spec.drive.controller_params(spec.method, spec.recursion)) as c:
        c.set(T_ref=1e9, w_m=0.0, u_dc=u_dc, T_magnet=spec.T_magnet, i_d=0.0, i_q=0.0)
        c.step(0.0, spec.step)
        return float(c.get("T_max"))


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
        return strict_json(self.to_dict())


def run_sweep(controller_fmu: Path, out: Path, spec: SweepSpec | None = None) -> SweepSummary:
    spec = spec if spec is not None else SweepSpec()
    spec = replace(spec, u_dc=spec.drive.controller.lut_u_dc if spec.u_dc is None else spec.u_dc)
    if spec.speeds_rpm is None:
        top = top_speed(controller_fmu, spec.drive) / RPM
        spec = replace(spec, speeds_rpm=(*(n for n in SPEEDS_RPM if n < top - 1.0), int(round(top))))
    if spec.T_overload is None:
        spec = replace(spec, T_overload=10.0 * math.ceil(
            OVERLOAD * reach_at_standstill(controller_fmu, spec, spec.u_dc) / 10.0))
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    torques = np.linspace(0.0, spec.T_overload, spec.n_torque)
    t0 = time.perf_counter()
    bar = Progress(len(spec.speeds()) * len(torques), "sweep")
    with Fmu(controller_fmu, **spec.drive.controller_params(spec.method, spec.recursion)) as c:
        k = 0
        for n in spec.speeds():
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
    def write_csv(tmp: Path) -> None:
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    write_atomically(out / "sweep.csv", write_csv)
    envelope = {n: max(r["T_max_Nm"] for r in rows if r["speed_rpm"] == n) for n in spec.speeds()}
    summary = SweepSummary(spec=spec.to_dict(), points=len(rows), wall_s=wall, T_max_Nm_by_speed_rpm=envelope,
                           P_max_kW_by_speed_rpm={n: T * n * RPM / 1e3 for n, T in envelope.items()})
    write_atomically(out / "summary.json", summary.to_json())
    plot_sweep(rows, spec, out / "current_trajectories.png")
    return summary


def plot_sweep(rows, spec: SweepSpec, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fmap = read_flux_map(spec.drive.motor.flux_map)
    motor = spec.drive.motor_data()
    p, R_s, I_max = motor.pole_pairs, motor.R_s, motor.I_max
    V_max = motor.k_u * spec.u_dc / math.sqrt(3)
    # the plane's window, scaled by the current limit (the default motor's 500 A: -560..100, -20..560)
    d_lo, d_hi, q_lo, q_hi = -1.12 * I_max, 0.2 * I_max, -0.04 * I_max, 1.12 * I_max

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(13, 5.6), gridspec_kw=dict(width_ratios=[1.15, 1]))
    th = np.linspace(0, 2 * np.pi, 400)
    ax.plot(I_max * np.cos(th), I_max * np.sin(th), "k--", lw=1, label=f"current limit {I_max:.0f} A")
    # Voltage ellipses (with saturation, from the flux map) and the trajectories, one colour per speed.
    g_d, g_q = np.meshgrid(np.linspace(d_lo, d_hi, 331), np.linspace(q_lo, q_hi, 291))
    psi_d, psi_q = fmap.flux(g_d, g_q)
    cmap = plt.get_cmap("viridis")
    speeds = [n for n in spec.speeds() if n > 0]
    for j, n in enumerate(spec.speeds()):
        color = cmap(j / max(1, len(spec.speeds()) - 1))
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
    ax.set_xlim(d_lo, d_hi)
    ax.set_ylim(q_lo, q_hi)
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
    write_atomically(path, lambda p: fig.savefig(p, format="png", dpi=120))
    plt.close(fig)
