"""Pictures of a drive-cycle run (from its trace.csv): what a drive engineer looks at."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from scenarios.core.boundary import write_atomically
from scenarios.core.paths import located
from scenarios.maps.flux_map import DEFAULT_MAP, read_flux_map

RPM = 2 * math.pi / 60  # rad/s per r/min
REGION_NAMES = {0: "zero torque", 1: "MTPA", 2: "voltage limit", 3: "current + voltage limit", 4: "MTPV"}


#: rows of trace.csv a figure draws at most: some 30 per pixel column of a run.png panel (about 600
#: pixels wide), more than the eye resolves; a standard cycle's trace (WLTC: 18 000 rows at 0.1 s)
#: is drawn whole, a week's (6 million rows) thinned to this
PLOT_MAX_ROWS = 20_000


def load_trace(path: Path, max_rows: int = PLOT_MAX_ROWS) -> dict:
    """trace.csv's columns (floats), read line by line and thinned to every k-th row, k doubling
    whenever more than `max_rows` rows are held: memory bounded by max_rows whatever the run's
    length (the first row always kept, the rows kept evenly spaced; a row is parsed only if kept)."""
    chunk = 4096  # rows parsed at once (numpy's C parser)
    held_rows: list[np.ndarray] = []
    held: list[np.ndarray] = []
    stride, count, pending, pending_rows = 1, 0, [], []

    def flush() -> None:
        nonlocal count, stride
        if pending:
            held_rows.append(np.array(pending_rows))
            held.append(np.loadtxt(pending, delimiter=",", ndmin=2, dtype=float))
            count += len(pending)
            pending.clear()
            pending_rows.clear()
        while count > max_rows:
            stride *= 2
            keep = [r % stride == 0 for r in held_rows]
            held_rows[:], held[:] = [r[m] for r, m in zip(held_rows, keep)], [d[m] for d, m in zip(held, keep)]
            count = sum(len(r) for r in held_rows)

    with open(path, encoding="utf-8") as f:
        names = f.readline().strip().split(",")
        for k, line in enumerate(f):
            if k % stride == 0 and line.strip():
                pending.append(line)
                pending_rows.append(k)
                if len(pending) == chunk:
                    flush()
        flush()
    data = np.concatenate(held) if held else np.empty((0, len(names)))
    return {n: data[:, i] for i, n in enumerate(names)}


def plot_run(run_dir: Path, title: str = "", drive=None) -> Path:
    """run.png in run_dir: speed tracking, torque, operating points on the envelope, currents in
    the i_d-i_q plane, u_dc and the region over time. The current limit, the voltage ellipses and
    the efficiency contours are the drive's own motor's (a scenarios.drives.description
    DriveDescription; None: the default drive)."""
    if drive is None:
        from scenarios.drives.description import load_drive
        drive = load_drive(None)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tr = load_trace(run_dir / "trace.csv")
    t = tr["time_s"]
    fig, ax = plt.subplots(3, 2, figsize=(14, 12))
    a = ax[0, 0]
    a.plot(t, tr["v_ref_mps"] * 3.6, "k-", lw=1.2, label="cycle")
    a.plot(t, tr["v_mps"] * 3.6, "C1--", lw=1, label="vehicle")
    a.set(xlabel="time (s)", ylabel="speed (km/h)", title="Speed tracking")
    a.legend()

    a = ax[0, 1]
    a.plot(t, tr["T_ref_Nm"], "k-", lw=0.8, label="T_ref (driver)")
    a.plot(t, tr["T_e_Nm"], "C3-", lw=0.8, alpha=0.8, label="T_e delivered")
    a.plot(t, tr["T_max_Nm"] * np.sign(tr["T_ref_Nm"] + 1e-12), "C0:", lw=0.8, label="±T_max")
    a.set(xlabel="time (s)", ylabel="torque (N·m)", title="Torque: demand and delivered")
    a.legend(fontsize=8)

    a = ax[1, 0]
    n_rpm = tr["w_m_rad_s"] / RPM
    sc = a.scatter(n_rpm, tr["T_e_Nm"], c=tr["region"], cmap="viridis", s=4, vmin=0, vmax=4)
    # envelope from the controller's T_max samples
    order = np.argsort(n_rpm)
    a.plot(n_rpm[order], np.maximum.accumulate(np.abs(tr["T_max_Nm"][order][::-1]))[::-1], "k-", lw=0.5, alpha=0.3)
    a.set(xlabel="speed (r/min)", ylabel="T_e (N·m)", title="Operating points (colour: region)")
    cb = fig.colorbar(sc, ax=a, ticks=list(REGION_NAMES))
    cb.ax.set_yticklabels([REGION_NAMES[k] for k in REGION_NAMES], fontsize=7)
    if drive.motor.w_m_max is not None:
        a.axvline(drive.motor.w_m_max / RPM, color="C3", ls=":", lw=0.8, label="top speed w_m_max")
        a.legend(fontsize=7, loc="upper right")
    if drive.motor.flux_map.resolve() == DEFAULT_MAP.resolve():
        _efficiency_background(a, run_dir)  # the default motor's map (docs/motor); none drawn for another motor

    a = ax[1, 1]
    _current_plane(a, tr, drive)
    a.set(xlabel="i_d (A)", ylabel="i_q (A)", title="Currents in the i_d–i_q plane", aspect="equal")
    a.legend(fontsize=7, loc="lower left")

    a = ax[2, 0]
    a.plot(t, tr["u_dc_V"], "C0-", lw=1)
    a.set(xlabel="time (s)", ylabel="u_dc (V)", title="DC-link voltage")
    a2 = a.twinx()
    a2.plot(t, tr["soc"] * 100, "C2--", lw=1)
    a2.set_ylabel("SOC (%)", color="C2")

    a = ax[2, 1]
    a.plot(t, tr["region"], "C4-", lw=0.6, drawstyle="steps-post")
    a.set_yticks(list(REGION_NAMES), [REGION_NAMES[k] for k in REGION_NAMES])
    a.set(xlabel="time (s)", title="Controller region")
    for row in ax:
        for a in row:
            a.grid(alpha=0.3)
    return save_figure(fig, title, run_dir / "run.png", dpi=100)


def save_figure(fig, title: str, path: Path, dpi: int) -> Path:
    """The figure titled, laid out, written to path and closed."""
    import matplotlib.pyplot as plt
    fig.suptitle(title)
    fig.tight_layout()
    try:
        write_atomically(path, lambda p: fig.savefig(p, format="png", dpi=dpi))
    finally:
        plt.close(fig)
    return path


#: the voltage ellipses drawn: these fractions of the top speed (the motor's w_m_max, else the run's
#: highest speed)
ELLIPSE_SPEEDS = (0.5, 0.75, 1.0)


def _current_plane(a, tr: dict, drive) -> None:
    """The run's currents on the drive's motor: its current limit and its voltage limit
    (k_u u_dc / sqrt 3 at the run's median u_dc) at ELLIPSE_SPEEDS of its top speed."""
    m = drive.motor
    fmap = read_flux_map(m.flux_map)
    I_max = m.I_max
    th = np.linspace(0, 2 * np.pi, 300)
    a.plot(I_max * np.cos(th), I_max * np.sin(th), "k--", lw=0.8, label=f"current limit {I_max:.0f} A")
    a.scatter(tr["i_d_A"], tr["i_q_A"], c=tr["region"], cmap="viridis", s=3, vmin=0, vmax=4)
    reach = 1.12 * I_max
    g_d = np.linspace(max(fmap.i_d[0], -reach), min(fmap.i_d[-1], reach), 240)
    g_q = np.linspace(max(fmap.i_q[0], -reach), min(fmap.i_q[-1], reach), 300)
    psi_d, psi_q = fmap.flux_on_grid(g_d, g_q)
    u_dc = float(np.median(tr["u_dc_V"]))
    V_max = drive.controller.k_u * u_dc / math.sqrt(3)
    w_top = m.w_m_max if m.w_m_max is not None else float(np.max(tr["w_m_rad_s"]))
    for frac, col in zip(ELLIPSE_SPEEDS, ("C2", "C1", "C3")):
        w = m.pole_pairs * frac * w_top
        if w <= 0:
            continue
        a.contour(g_d, g_q, np.hypot(w * psi_q, w * psi_d).T, levels=[V_max], colors=[col], linewidths=0.8)
        a.plot([], [], color=col, lw=0.8, label=f"voltage limit {frac * w_top / RPM:.0f} r/min, {u_dc:.0f} V")


def _efficiency_background(ax, run_dir: Path) -> None:
    """The motor's efficiency map (docs/motor, brute force over the map) as grey contours, if present."""
    import json
    p = located("docs/motor/efficiency_map.json")
    if not p.exists():
        return
    d = json.loads(p.read_text())
    eta = np.array([[np.nan if e is None else e for e in row] for row in d["efficiency"]], float)  # rows: torque
    T = np.array(d["torque_Nm"])
    n = np.array(d["speed_rpm"])
    # Motoring map; regenerating points are drawn against its mirror image (same losses, to first order).
    cs = ax.contour(n, T, eta * 100, levels=[80, 85, 90, 93, 95, 96], colors="0.6", linewidths=0.6)
    ax.contour(n, -T, eta * 100, levels=[80, 85, 90, 93, 95, 96], colors="0.6", linewidths=0.6, linestyles=":")
    ax.clabel(cs, fontsize=6, fmt="%g %%")
