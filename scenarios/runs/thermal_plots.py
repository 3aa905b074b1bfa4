"""thermal.png beside run.png (from trace.csv) when the thermal network was on: the machine's node
temperatures, the torque limit's derating and the power the driver asked for against what the
drive delivered, over time."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from scenarios.core.constants import ZERO_CELSIUS_K
from scenarios.runs.plots import load_trace, save_figure

#: the trace's node temperatures and their labels
NODES = (("theta_winding_K", "winding"), ("theta_stator_tooth_K", "stator teeth"),
         ("theta_stator_yoke_K", "stator yoke"), ("theta_magnet_K", "magnets (rotor)"))


def plot_thermal(run_dir: Path, title: str = "", T_coolant: float | None = None) -> Path:
    """thermal.png in run_dir; T_coolant (K) drawn as the network's boundary when given."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tr = load_trace(run_dir / "trace.csv")
    t_min = tr["time_s"] / 60.0
    fig, ax = plt.subplots(3, 1, figsize=(12, 11), sharex=True)
    a = ax[0]
    for col, label in NODES:
        a.plot(t_min, tr[col] - ZERO_CELSIUS_K, lw=1.2, label=label)
    if T_coolant is not None:
        a.axhline(T_coolant - ZERO_CELSIUS_K, color="k", ls=":", lw=0.8, label="coolant")
    a.set(ylabel="temperature (°C)", title="The machine's thermal network: node temperatures")
    a.legend(fontsize=8, loc="upper left")
    a.grid(alpha=0.3)

    a = ax[1]
    a.plot(t_min, tr["derating"], "C3-", lw=1.2, label="derating (torque limit's thermal factor)")
    a.set_ylim(-0.05, 1.05)
    a2 = a.twinx()
    a2.plot(t_min, np.abs(tr["T_max_Nm"]), "C0-", lw=0.6, alpha=0.6, label="T_max")
    a2.set_ylabel("T_max (N·m)", color="C0")
    a.set(ylabel="derating (1: none)", title="Derating")
    a.legend(fontsize=8, loc="lower left")
    a.grid(alpha=0.3)

    a = ax[2]
    a.plot(t_min, tr["P_demand_W"] / 1e3, "k-", lw=0.8, label="requested (driver, at the wheels)")
    a.plot(t_min, tr["P_wheel_W"] / 1e3, "C1-", lw=0.8, alpha=0.8, label="delivered (drive, at the wheels)")
    a.plot(t_min, tr["P_coolant_W"] / 1e3, "C2-", lw=0.8, label="heat into the coolant")
    # the driver's demand is a controller's output, unbounded while the car cannot follow (a
    # full-power climb): the axis is the delivered power's
    lim = 1.3 * max(np.nanmax(np.abs(tr["P_wheel_W"])), 1.0) / 1e3
    a.set(xlabel="time (min)", ylabel="power (kW)", title="Power: requested, delivered, and heat to the coolant",
          ylim=(-lim, lim))
    a.legend(fontsize=8, loc="upper left")
    a.grid(alpha=0.3)
    return save_figure(fig, title, run_dir / "thermal.png", dpi=90)
