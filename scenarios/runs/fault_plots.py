"""The picture of a fault in a run (from its fault_trace.csv, scenarios.runs.fault): speed and
inverter state, currents, torque, DC current and temperatures around the trip."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from scenarios.runs.fault import INVERTER_STATES
from scenarios.runs.plots import load_trace, save_figure


def plot_fault(run_dir: Path, title: str = "", summary: dict | None = None, i_d_demag: float | None = None) -> Path:
    """fault.png in run_dir; `summary` (the run's summary dict) marks the trip and its figures;
    i_d_demag (A) draws the magnets' limit on the currents' panel."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tr = load_trace(run_dir / "fault_trace.csv")
    t = tr["time_s"]
    fig, ax = plt.subplots(5, 1, figsize=(11, 14), sharex=True)
    t_trip = (summary or {}).get("fault_time_s")

    a = ax[0]
    a.plot(t, tr["v_kmh"], "C1-", lw=1.2)
    a.set(ylabel="vehicle speed (km/h)", title="Speed and inverter state")
    a2 = a.twinx()
    a2.plot(t, tr["inverter_state"], "C4-", lw=1, drawstyle="steps-post")
    a2.set_yticks(list(INVERTER_STATES), list(INVERTER_STATES.values()))
    a2.set_ylim(-0.3, 2.3)

    a = ax[1]
    a.plot(t, tr["i_d_A"], "C0-", lw=1, label="i_d (step end)")
    a.plot(t, tr["i_q_A"], "C2-", lw=1, label="i_q (step end)")
    a.plot(t, tr["i_peak_A"], "C3--", lw=1, label="i_peak (largest |i| since the trip)")
    if i_d_demag is not None and math.isfinite(i_d_demag):
        a.axhline(i_d_demag, color="k", ls=":", lw=1, label=f"i_d_demag {i_d_demag:.0f} A")
    a.set(ylabel="current (A)", title="Phase currents (dq, peak)")
    a.legend(fontsize=8, loc="best")

    a = ax[2]
    a.plot(t, tr["T_e_Nm"], "C3-", lw=1, label="T_e")
    a.plot(t, tr["T_shaft_Nm"], "C0--", lw=1, label="T_shaft")
    a.set(ylabel="torque (N·m)", title="Torque (10 ms means; < 0: braking)")
    a.legend(fontsize=8)

    a = ax[3]
    a.plot(t, tr["i_dc_A"], "C2-", lw=1)
    a.axhline(0.0, color="k", lw=0.5)
    a.set(ylabel="i_dc (A)", title="DC-link current of the drive (< 0: into the battery)")

    a = ax[4]
    if np.all(np.isfinite(tr["theta_winding_K"])):
        a.plot(t, tr["theta_winding_K"] - 273.15, "C3-", lw=1, label="winding")
        a.plot(t, tr["theta_magnet_K"] - 273.15, "C1-", lw=1, label="magnets")
        a.legend(fontsize=8)
    a.set(xlabel="time (s)", ylabel="temperature (°C)", title="Temperatures (the thermal network's; off: held)")
    for a in ax:
        a.grid(alpha=0.3)
        if t_trip is not None:
            a.axvline(t_trip, color="k", ls="--", lw=0.8)
    if summary and t_trip is not None:
        ax[0].text(0.01, 0.05, f"trip at {t_trip:.2f} s, {summary['fault_speed_kmh']:.1f} km/h: "
                   f"{summary['fault_state']}; peak {summary['fault_i_peak_A']:.0f} A, braking "
                   f"{summary['fault_T_peak_Nm']:.0f} N·m, {summary['fault_charge_Ah']:.3g} Ah into the battery",
                   transform=ax[0].transAxes, fontsize=8)
    return save_figure(fig, title, run_dir / "fault.png", dpi=100)
