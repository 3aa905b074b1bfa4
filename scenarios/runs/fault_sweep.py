"""`python -m scenarios sweep --fault`: the safe-state envelope of a drive (docs/faults.md).

For each speed on a grid up to the motor's top speed, for freewheeling and for ASC, and from two
operating points (full load: the controller's T_max at that speed; no load), one IpmsmDrive
instance runs at the held speed until the current regulator has settled, then its `fault` input
goes on with `safe_state` forcing the state (contract, "Faults"), and it runs until the fault's
currents are steady. Per point: the transient's peak current (IpmsmDrive's `i_peak`, resolved at
its sample time), the steady braking torque, the steady DC-link current (< 0: charging) and the
steady current. Written: fault_sweep.csv, summary.json (the onset of uncontrolled generation, the
envelope's extremes) and fault_envelope.png.
"""
from __future__ import annotations

import csv
import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from scenarios.core.boundary import strict_json, write_atomically
from scenarios.core.constants import T_REFERENCE_K
from scenarios.core.progress import Progress
from scenarios.cosim.drive_fmu import DriveFmu
from scenarios.cosim.fmu import CosimError
from scenarios.drives.description import SAFE_STATES, DriveDescription, load_drive
from scenarios.runs.fault import ZERO_CURRENT_FRACTION, demagnetisation_limit
from scenarios.vehicle.longitudinal import vehicle_speed

RPM = math.pi / 30.0  # rad/s per r/min

#: r/min between the sweep's speeds (the top speed is added) ...
SPEED_STEP_RPM = 500.0
#: ... and the low speeds before them: ASC's braking torque peaks near w_e = R_s / L_q (about
#: 21 rad/s electrical, 50 r/min, on the default motor: 0.012 Ohm, L_q 0.57 mH at small i_q),
#: far below the first step
LOW_SPEEDS_RPM = (25.0, 50.0, 100.0, 200.0, 300.0)
#: the forced states swept (IpmsmDrive's safe_state by name)
STATES = ("freewheel", "asc")
#: the operating points before the trip: full load (a torque command beyond reach: the controller
#: gives T_max at the speed) and no load
LOADS = {"full_load": 1e9, "no_load": 0.0}
#: s, before the trip: the current regulator (500 Hz bandwidth by default) settles in a few ms
SETTLE_S = 0.05
#: s, after the trip: ASC's slowest time constant L_q / R_s is some 47 ms on the default motor
#: (0.57 mH / 0.012 Ohm): 0.5 s is 10 of them, a residual of e^-10 (`steady` checks it per point)
FAULT_S = 0.5
#: s, the communication step (the steady figures are the last one's means)
STEP_S = 0.01
#: characters of an FMU's error kept per failed point (its log line is bounded; a CSV cell stays readable)
ERROR_CHARS = 500
#: the steady state is reached when the last two steps' mean torques differ by less than this
#: share of the larger (or by less than 1e-6 N m)
STEADY_TOLERANCE = 1e-3


@dataclass
class FaultSweepSpec:
    """What to sweep: the drive's motor, inverter and controller (a drive description) at u_dc
    (None: the drive's controller.lut_u_dc) and the temperatures (K; 20 degC: the strongest
    magnets, the largest currents and torques); speeds (r/min; None: SPEED_STEP_RPM steps to the
    drive's top speed)."""

    drive: DriveDescription = field(default_factory=load_drive)
    speeds_rpm: tuple | None = None
    u_dc: float | None = None
    T_magnet: float = T_REFERENCE_K
    T_winding: float = T_REFERENCE_K

    def to_dict(self) -> dict:
        return dict({k: v for k, v in asdict(self).items() if k != "drive"}, drive=self.drive.name)


def speeds_up_to(top_rpm: float, step: float = SPEED_STEP_RPM) -> tuple:
    n = int(math.floor(top_rpm / step + 1e-9))
    grid = [x for x in LOW_SPEEDS_RPM if x < top_rpm] + [step * k for k in range(1, n + 1)]
    return tuple(grid if grid and abs(grid[-1] - top_rpm) < 1e-6 else [*grid, top_rpm])


def fault_point(drive_fmu: Path, spec: FaultSweepSpec, params: dict, state: str, load: str, rpm: float) -> dict:
    """One point of the envelope: settle at the operating point, trip, run to the steady state."""
    w_m = rpm * RPM
    inputs = dict(T_ref=LOADS[load], w_m=w_m, u_dc=spec.u_dc, T_magnet=spec.T_magnet, T_winding=spec.T_winding)
    with DriveFmu(drive_fmu, {**params, "safe_state": SAFE_STATES[state]}, **inputs, instance_name="fault_sweep") as d:
        before = None
        for _ in range(int(round(SETTLE_S / STEP_S))):
            before = d.advance(STEP_S, **inputs)
        d.set_fault(True)
        inputs["T_ref"] = 0.0
        steps = [d.advance(STEP_S, **inputs) for _ in range(int(round(FAULT_S / STEP_S)))]
    last, prev = steps[-1], steps[-2]
    steady = abs(last.T_shaft - prev.T_shaft) <= max(STEADY_TOLERANCE * max(abs(last.T_shaft), abs(prev.T_shaft)),
                                                     1e-6)
    return dict(speed_rpm=rpm, state=state, load=load, error="", T_before_Nm=before.T_e,
                I_before_A=math.hypot(before.i_d, before.i_q), inverter_state=last.inverter_state,
                i_peak_A=max(s.i_peak for s in steps),
                T_shaft_steady_Nm=last.T_shaft, T_e_steady_Nm=last.T_e, i_dc_steady_A=last.i_dc,
                P_dc_steady_W=last.P_dc, i_d_steady_A=last.i_d, i_q_steady_A=last.i_q,
                I_steady_A=math.hypot(last.i_d, last.i_q), P_cu_steady_W=last.P_cu, P_fe_steady_W=last.P_fe,
                P_inv_steady_W=last.P_inv, steady=steady)


@dataclass(frozen=True)
class FaultSweepSummary:
    """summary.json of a fault sweep: the spec, the points, the onset of uncontrolled generation
    (the lowest speed swept at which freewheeling from no load carries a current), and per state
    the largest peak current, braking torque and charging current over the speeds."""

    spec: dict
    points: int
    wall_s: float
    i_d_demag_A: float | None
    onset_back_emf_rpm: float     # where the back-EMF's line-to-line peak sqrt(3) p w_m psi_m reaches u_dc
    onset_back_emf_kmh: float     # ... the drive's car at that motor speed
    onset_fundamental_rpm: float  # where p w_m psi_m reaches the conducting bridge's 2 u_dc / pi (the plant's model)
    onset_rpm: float | None
    envelope: dict   # state -> {i_peak_A_max, T_brake_Nm_max, i_dc_charge_A_max, ...} over the points that ran
    failed: list     # [state, load, speed_rpm, error] of the points the FMU could not run

    def to_json(self) -> str:
        return strict_json(asdict(self))


#: a row's figures when its point could not run (the FMU refused a step): NaN, `error` says why
FIGURES = ("T_before_Nm", "I_before_A", "inverter_state", "i_peak_A", "T_shaft_steady_Nm", "T_e_steady_Nm",
           "i_dc_steady_A", "P_dc_steady_W", "i_d_steady_A", "i_q_steady_A", "I_steady_A", "P_cu_steady_W",
           "P_fe_steady_W", "P_inv_steady_W")


def failed_point(state: str, load: str, rpm: float, error: str) -> dict:
    return dict(speed_rpm=rpm, state=state, load=load, error=error, **{k: math.nan for k in FIGURES}, steady=False)


def envelope(rows: list[dict], I_max: float) -> tuple[float | None, dict]:
    """(the onset speed, per state the extremes) of the rows that ran (None: no row ran)."""
    zero = ZERO_CURRENT_FRACTION * I_max
    rows = [r for r in rows if not r["error"]]
    onset = next((r["speed_rpm"] for r in sorted(rows, key=lambda r: r["speed_rpm"])
                  if r["state"] == "freewheel" and r["load"] == "no_load" and r["I_steady_A"] > zero), None)
    out = {}
    for state in STATES:
        sel = [r for r in rows if r["state"] == state]
        if not sel:
            out[state] = None
            continue
        peak = max(sel, key=lambda r: r["i_peak_A"])
        brake = max(sel, key=lambda r: -r["T_shaft_steady_Nm"])
        charge = max(sel, key=lambda r: -r["i_dc_steady_A"])
        out[state] = dict(i_peak_A_max=peak["i_peak_A"], i_peak_at_rpm=peak["speed_rpm"], i_peak_from=peak["load"],
                          T_brake_Nm_max=-brake["T_shaft_steady_Nm"], T_brake_at_rpm=brake["speed_rpm"],
                          i_dc_charge_A_max=-charge["i_dc_steady_A"], i_dc_charge_at_rpm=charge["speed_rpm"],
                          all_steady=all(r["steady"] for r in sel))
    return onset, out


def onset_speed(drive: DriveDescription, spec: FaultSweepSpec) -> float:
    """rad/s, the motor speed at which the back-EMF's line-to-line peak sqrt(3) p w_m psi_m
    reaches u_dc (contract, "Faults": the policy's boundary), psi_m the map's flux at zero current
    at the sweep's magnet temperature (the plant's law: 1 + k_psi_T (T - T_magnet_ref))."""
    from scenarios.maps.flux_map import read_flux_map
    m = drive.motor
    psi_d, psi_q = read_flux_map(m.flux_map).flux(0.0, 0.0)
    psi_m = math.hypot(float(psi_d), float(psi_q)) * (1.0 + m.k_psi_T * (spec.T_magnet - m.T_magnet_ref))
    return spec.u_dc / (math.sqrt(3.0) * m.pole_pairs * psi_m)


def run_fault_sweep(drive_fmu: Path, out: Path, spec: FaultSweepSpec | None = None,
                    progress: bool = True) -> FaultSweepSummary:
    spec = spec if spec is not None else FaultSweepSpec()
    drive = spec.drive
    spec = replace(spec, u_dc=drive.controller.lut_u_dc if spec.u_dc is None else spec.u_dc)
    params = {**drive.controller_params(), **drive.plant_params(), "sample_time": 1e-4,
              **(drive.fault.fmu_params() if drive.fault is not None else {})}
    if spec.speeds_rpm is None:
        with DriveFmu(drive_fmu, params) as d:  # the top speed: the drive's, else the FMU's default
            top = d.get("w_m_max") / RPM
        spec = replace(spec, speeds_rpm=speeds_up_to(top))
    out.mkdir(parents=True, exist_ok=True)
    points = [(s, load, n) for s in STATES for load in LOADS for n in spec.speeds_rpm]
    bar = Progress(len(points), "fault sweep") if progress else None
    t0 = time.perf_counter()
    rows = []
    for state, load, n in points:
        try:
            rows.append(fault_point(drive_fmu, spec, params, state, load, float(n)))
        except CosimError as e:  # the FMU refused a step: the point has no figures, and says why
            rows.append(failed_point(state, load, float(n), str(e)[:ERROR_CHARS]))
        if bar:
            bar.update()
    if bar:
        bar.close()
    wall = time.perf_counter() - t0
    with DriveFmu(drive_fmu, params) as d:
        i_d_demag = demagnetisation_limit(d)

    def write(tmp: Path) -> None:
        with open(tmp, "w", newline="", encoding="utf-8") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    write_atomically(out / "fault_sweep.csv", write)
    onset, env = envelope(rows, drive.motor.I_max)
    w_onset = onset_speed(drive, spec)
    summary = FaultSweepSummary(spec=spec.to_dict(), points=len(rows), wall_s=wall, i_d_demag_A=i_d_demag,
                                onset_back_emf_rpm=w_onset / RPM,
                                onset_back_emf_kmh=3.6 * vehicle_speed(w_onset, drive.vehicle),
                                onset_fundamental_rpm=w_onset * math.sqrt(3.0) * 2.0 / math.pi / RPM,
                                onset_rpm=onset, envelope=env,
                                failed=[[r["state"], r["load"], r["speed_rpm"], r["error"]]
                                        for r in rows if r["error"]])
    write_atomically(out / "summary.json", summary.to_json())
    plot_fault_envelope(rows, summary, drive.motor.I_max, out / "fault_envelope.png")
    return summary


def plot_fault_envelope(rows: list[dict], summary: FaultSweepSummary, I_max: float, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 3, figsize=(16, 5))
    style = {"freewheel": "C0", "asc": "C3"}
    for state in STATES:
        for load, ls in (("full_load", "-"), ("no_load", "--")):
            sel = sorted((r for r in rows if r["state"] == state and r["load"] == load), key=lambda r: r["speed_rpm"])
            n = [r["speed_rpm"] for r in sel]
            ax[0].plot(n, [r["i_peak_A"] for r in sel], ls, color=style[state], marker=".",
                       label=f"{state}, from {load.replace('_', ' ')}")
            if load == "no_load":
                ax[1].plot(n, [-r["T_shaft_steady_Nm"] for r in sel], "-", color=style[state], marker=".", label=state)
                ax[2].plot(n, [-r["i_dc_steady_A"] for r in sel], "-", color=style[state], marker=".", label=state)
    ax[0].axhline(I_max, color="k", ls=":", lw=1, label=f"I_max {I_max:.0f} A")
    if summary.i_d_demag_A is not None:
        ax[0].axhline(abs(summary.i_d_demag_A), color="C1", ls="-.", lw=1,
                      label=f"|i_d_demag| {abs(summary.i_d_demag_A):.0f} A")
    for a in ax[1:]:
        if summary.onset_rpm is not None:
            a.axvline(summary.onset_rpm, color="k", ls=":", lw=0.8, label=f"onset {summary.onset_rpm:.0f} r/min")
    ax[0].set(title="Peak current after the trip", ylabel="|i| peak (A)")
    ax[1].set(title="Steady braking torque", ylabel="-T_shaft (N·m)")
    ax[2].set(title="Steady charging current (DC link)", ylabel="-i_dc (A)")
    for a in ax:
        a.set_xlabel("speed (r/min)")
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    u_dc = summary.spec["u_dc"]
    fig.suptitle(f"Safe-state envelope of {summary.spec['drive']} at {u_dc:.0f} V, magnets at "
                 f"{summary.spec['T_magnet'] - 273.15:.0f} °C")
    fig.tight_layout()
    write_atomically(path, lambda p: fig.savefig(p, format="png", dpi=110))
    plt.close(fig)
