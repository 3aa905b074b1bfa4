"""python -m scenarios {run, sweep}: one drive cycle (summary.json, trace.csv, run.png) and the
controller's torque-speed sweep. A bad drive description or number exits 2 naming the file or
option and the key (the caller, scenarios.__main__, turns InputError into that)."""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from scenarios.core.boundary import InputError, check_writable, finite, inside
from scenarios.core.constants import T_REFERENCE_K, U_DC_SCALE_MAX, ZERO_CELSIUS_K
from scenarios.core.paths import FMU_FOLDERS, OUT_DIR
from scenarios.cosim import BACKEND_ALIASES, BACKENDS, backend_name

DRIVE_HELP = "drive description (TOML, docs/drives.md); default: scenarios/drives/default.toml"
#: run --repeat: at most this many copies of a cycle (100 WLTCs are 50 h of driving: no thermal
#: run needs more, and the vehicle side's memory and time stay bounded)
REPEAT_MAX = 100
#: the contract's summary keys (docs/spec/INTERFACE.md) and the real-time factor: what `run` prints
RUN_PRINTED = ("cycle", "method", "objective", "distance_km", "energy_battery_Wh", "Wh_per_km", "speed_rmse_mps",
               "torque_rmse_Nm", "torque_error_max_Nm", "copper_loss_Wh", "iron_loss_Wh", "inverter_loss_Wh",
               "drive_loss_Wh", "w_m_peak_rpm", "time_above_top_speed_s", "steps", "wall_s", "real_time_factor")
#: ... and with the thermal network on
THERMAL_PRINTED = ("theta_winding_max_K", "theta_magnet_max_K", "theta_winding_end_K", "theta_magnet_end_K",
                   "heat_coolant_Wh", "heat_balance_residual_Wh", "time_derated_s", "derating_min")
#: ... and with a [fault] table (docs/faults.md)
FAULT_PRINTED = ("fault_trigger", "fault_safe_state", "fault_time_s", "fault_speed_kmh", "fault_state",
                 "fault_state_end", "fault_i_peak_A", "fault_demag_margin_A", "fault_T_peak_Nm", "fault_charge_Ah",
                 "fault_energy_Wh", "fault_time_to_zero_current_s")
#: exit status of a sweep --fault with a point the FMU could not run (its files written)
EXIT_FAILED = 1


def add_parsers(sub) -> None:
    sw = sub.add_parser("sweep", help="torque-speed sweep of the controller: table and plot of the optimal currents")
    sw.add_argument("--out", type=Path, default=None, help="default: out/sweep (with --fault: out/sweep_fault)")
    sw.add_argument("--recursion", type=int, default=2, choices=(0, 1, 2))
    sw.add_argument("--u-dc", type=float, default=None, help="V; default: the drive's controller.lut_u_dc")
    sw.add_argument("--drive", type=Path, default=None, help=DRIVE_HELP)
    sw.add_argument("--fault", action="store_true", help="the safe-state envelope instead (docs/faults.md): peak "
                    "current, braking torque and charging current against speed, freewheeling and ASC")

    run = sub.add_parser("run", help="one drive cycle: summary.json, trace.csv, run.png")
    run.add_argument("cycle", help="WLTC3b, UDDS, HWFET, US06, NEDC, or a CSV of time_s,speed_mps")
    run.add_argument("--drive", type=Path, default=None, help=DRIVE_HELP)
    run.add_argument("--method", default=None, choices=("ferrari", "lut_speed", "lut_flux"),
                     help="default: the drive's controller.method")
    run.add_argument("--recursion", type=int, default=None, choices=(0, 1, 2),
                     help="default: the drive's controller.recursion")
    run.add_argument("--objective", default=None, choices=("current", "loss"),
                     help="least current or least loss (docs/least_loss.md); default: the drive's controller.objective")
    run.add_argument("--controller-loss-scale", type=float, default=1.0,
                     help="the controller's loss coefficients (iron, inverter) over the plant's, e.g. 1.3: a loss "
                          "model 30 %% off (needs --backend reference, where the two can differ); default 1")
    run.add_argument("--backend", default="drive", choices=BACKENDS + tuple(BACKEND_ALIASES),
                     help="drive: the IpmsmDrive FMU stepped at the vehicle's 10 ms (the fast path); reference "
                          "(or fmpy, its former name): the reference loop, IpmsmController and IpmsmPlant coupled "
                          "at 100 us in Python (slow)")
    run.add_argument("--fmi", type=int, default=2, choices=tuple(FMU_FOLDERS),
                     help="the FMUs' FMI version: 2 (build/fmu, the default) or 3 (build/fmu3); the same results")
    run.add_argument("--u-dc-scale", type=float, default=1.0, help="DC voltage seen by the drive / battery's")
    run.add_argument("--magnet-degC", type=float, default=T_REFERENCE_K - ZERO_CELSIUS_K)
    run.add_argument("--repeat", type=int, default=1, help="drive the cycle this many times in a row (thermal "
                     "runs: repeated US06, a motorway phase); default 1")
    run.add_argument("--out", type=Path, default=None)


def slug(text: str) -> str:
    """A file-name part of `text`: letters, digits, '.', '-' and '_' only (a drive named
    x/../../evil stays one name inside out/)."""
    s = re.sub(r"_{2,}", "_", re.sub(r"[^A-Za-z0-9._-]+", "_", re.sub(r"\.{2,}", "_", text))).strip("._") or "run"
    return s[:100]


def number_as_key(value: float | None, option: str, key: str) -> None:
    """A command-line number checked by a drive-description key's rule (None: not given)."""
    from scenarios.drives.description import SCHEMA
    if value is None:
        return
    bad = next(k.rule for k in SCHEMA if k.path == key).check(value)
    if bad:
        raise InputError("(command line)", option, bad + ("" if "got" in bad else f", got {value!r}"))


def cycle_arg(name: str, option: str):
    """A cycle named on the command line, loaded (a missing or malformed one: exit 2)."""
    from scenarios.vehicle.cycles import load_cycle
    try:
        return load_cycle(name)
    except InputError:
        raise
    except (OSError, ValueError) as e:
        raise InputError("(command line)", option, f"a standard cycle or a CSV of time_s,speed_mps ({e})") from None


def _run_args(args) -> None:
    """run's numbers, refused (exit 2) before anything runs."""
    from scenarios.core.fmu_ranges import fmu_ranges
    finite(args.u_dc_scale, "(command line)", "--u-dc-scale", 0.0, U_DC_SCALE_MAX, lo_open=True)
    r = fmu_ranges()["T_magnet_ref"]  # the FMUs' temperature range
    finite(args.magnet_degC, "(command line)", "--magnet-degC", r.lo - ZERO_CELSIUS_K, r.hi - ZERO_CELSIUS_K)
    from scenarios.runs.simulate import CONTROLLER_LOSS_SCALE_MAX
    finite(args.controller_loss_scale, "(command line)", "--controller-loss-scale", 0.0, CONTROLLER_LOSS_SCALE_MAX,
           lo_open=True)
    if args.controller_loss_scale != 1.0 and backend_name(args.backend) != "reference":
        raise InputError("(command line)", "--controller-loss-scale", "--backend reference (IpmsmDrive declares the "
                         "loss parameters once for the controller and the plant)")
    if not 1 <= args.repeat <= REPEAT_MAX:
        raise InputError("(command line)", "--repeat", f"an integer in [1, {REPEAT_MAX}], got {args.repeat}")


def objective_arg(objective: str | None, drive) -> str:
    """--objective (None: the drive's); least loss only with FMUs that have it (else exit 2)."""
    from scenarios.drives.description import OBJECTIVE_DEFAULT, controller_has_objective
    objective = objective or drive.controller.objective
    if objective != OBJECTIVE_DEFAULT and not controller_has_objective():
        raise InputError("(command line)", "--objective", "a value the built FMUs have: rebuild them (their model "
                         "descriptions have no `objective` parameter)")
    return objective


def main(args) -> int:
    """`run` or `sweep` (args.cmd)."""
    return {"run": run, "sweep": sweep}[args.cmd](args)


def sweep(args) -> int:
    from scenarios.drives.fmu_acceptance import load_accepted
    from scenarios.runs.sweep import SweepSpec, run_sweep
    number_as_key(args.u_dc, "--u-dc", "controller.lut_u_dc")
    drive = load_accepted(args.drive, args.build)
    args.out = args.out or OUT_DIR / ("sweep_fault" if args.fault else "sweep")
    check_writable(args.out)
    if args.fault:
        return fault_sweep(args, drive)
    s = run_sweep(args.build / "fmu" / "IpmsmController.fmu", args.out,
                  SweepSpec(drive=drive, recursion=args.recursion, u_dc=args.u_dc))
    print(json.dumps({k: s.to_dict()[k] for k in ("points", "wall_s", "T_max_Nm_by_speed_rpm")}, indent=1))
    print(f"wrote {args.out}/sweep.csv, summary.json, current_trajectories.png")
    return 0


def fault_sweep(args, drive) -> int:
    """sweep --fault: the safe-state envelope (scenarios.runs.fault_sweep); exit 1 when a point
    could not run (its row and summary.json say why)."""
    from scenarios.runs.fault_sweep import FaultSweepSpec, run_fault_sweep
    f = run_fault_sweep(args.build / "fmu" / "IpmsmDrive.fmu", args.out, FaultSweepSpec(drive=drive, u_dc=args.u_dc))
    keys = ("points", "wall_s", "i_d_demag_A", "onset_back_emf_rpm", "onset_back_emf_kmh", "onset_fundamental_rpm",
            "onset_rpm", "envelope")
    print(json.dumps({k: getattr(f, k) for k in keys}, indent=1))
    print(f"wrote {args.out}/fault_sweep.csv, summary.json, fault_envelope.png")
    for state, load, n, error in f.failed:
        print(f"error: {state} from {load} at {n:g} r/min could not run: {error}", file=sys.stderr)
    return EXIT_FAILED if f.failed else 0


def _below_derating_zero(T: float, drive) -> None:
    """--magnet-degC sets the magnets and the winding: below where the drive's derating takes the
    whole torque (thermal.T_magnet_max, T_winding_max), or the car could not move at all."""
    for name in ("T_magnet_max", "T_winding_max"):
        T_max = drive.thermal.values.get(name)
        if T_max is not None and T >= T_max:
            raise InputError("(command line)", "--magnet-degC", f"a temperature below the drive's thermal.{name} = "
                             f"{T_max - ZERO_CELSIUS_K:g} degC (its torque limit is zero there: the car could not "
                             f"move), got {T - ZERO_CELSIUS_K:g}")


def run(args) -> int:
    from scenarios.drives.fmu_acceptance import load_accepted
    from scenarios.runs.out_folder import run_folder
    from scenarios.runs.plots import plot_run
    from scenarios.runs.simulate import Conditions, RunSpec, fmu_paths, simulate
    from scenarios.vehicle.cycles import repeated
    _run_args(args)
    drive = load_accepted(args.drive, args.build)
    method = args.method or drive.controller.method
    objective = objective_arg(args.objective, drive)
    T = args.magnet_degC + ZERO_CELSIUS_K
    _below_derating_zero(T, drive)
    custom = (args.u_dc_scale, T) != (1.0, T_REFERENCE_K)
    cond = Conditions("custom" if custom else "nominal", u_dc_scale=args.u_dc_scale, T_magnet=T, T_winding=T)
    cycle = cycle_arg(args.cycle, "cycle")
    try:
        cycle = repeated(cycle, args.repeat)
    except ValueError as e:
        raise InputError("(command line)", "--repeat", str(e)) from None
    stem = Path(args.cycle).stem + ("" if args.repeat == 1 else f"_x{args.repeat}") + (
        "" if args.drive is None else f"_{drive.name}")
    stem += "" if objective == "current" else f"_least_{objective}"
    stem += "" if args.fmi == 2 else f"_fmi{args.fmi}"
    out = args.out or inside(OUT_DIR, slug(f"{stem}_{method}"), "run's output folder")
    with run_folder(out) as folder:  # one run at a time, holding one run (scenarios.runs.out_folder)
        s = simulate(cycle, RunSpec(drive=drive, method=method, recursion=args.recursion, conditions=cond,
                                    backend=args.backend, objective=objective,
                                    controller_loss_scale=args.controller_loss_scale),
                     fmus=fmu_paths(args.build, args.fmi), out=out)
        title = f"{s.cycle}, {method}" + ("" if objective == "current" else f", least {objective}") + (
            "" if args.drive is None else f", {drive.name}")
        plot_run(out, title, drive)
        written = ["summary.json", "trace.csv", "run.png"]
        if s.thermal_network:
            from scenarios.runs.thermal_plots import plot_thermal
            plot_thermal(out, title, drive.thermal.T_coolant)
            written.append("thermal.png")
        d = s.to_dict()
        if drive.fault is not None:
            from scenarios.runs.fault_plots import plot_fault
            written.append("fault_trace.csv")
            if s.fault_time_s is None:
                print(f"warning: no fault in this run: {drive.fault.describe()} never reached", file=sys.stderr)
            else:
                plot_fault(out, title, d, s.fault_i_d_demag_A)
                written.append("fault.png")
        folder.done(tuple(written))
    for a in drive.assumed:
        print(f"assumed: {a}", file=sys.stderr)
    print(json.dumps({k: d[k] for k in RUN_PRINTED + (THERMAL_PRINTED if s.thermal_network else ()) +
                      (FAULT_PRINTED if drive.fault is not None else ())}, indent=1))
    print(f"wrote {out}/" + ", ".join(written))
    return 0
