"""python -m scenarios {sweep, run, compare, check, study, map, fmu-path} ... (see --help of each). A bad drive
description or input exits 2 with the file, the key and what was expected."""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from scenarios.core.constants import T_REFERENCE_K, U_DC_SCALE_MAX, ZERO_CELSIUS_K
from scenarios.core.paths import BUILD_DIR, OUT_DIR
from scenarios.core.version import VERSION
from scenarios.cosim import BACKENDS
from scenarios.maps import cli as map_cli

DRIVE_HELP = "drive description (TOML, docs/drives.md); default: scenarios/drives/default.toml"

#: exit status: bad input (file, key, what was expected); a run that could not finish
EXIT_BAD_INPUT, EXIT_FAILED = 2, 1
#: run --repeat: at most this many copies of a cycle (100 WLTCs are 50 h of driving: no thermal
#: run needs more, and the vehicle side's memory and time stay bounded)
REPEAT_MAX = 100
#: what `fmu-path` finds: the FMUs (build/fmu/NAME.fmu) and the SSP package (build/ssp/NAME.ssp)
FMU_NAMES = ("IpmsmController", "IpmsmPlant", "IpmsmDrive")
SSP_NAME = "IpmsmControllerPlant"

#: the contract's summary keys (docs/spec/INTERFACE.md) and the real-time factor: what `run` prints
RUN_PRINTED = ("cycle", "method", "objective", "distance_km", "energy_battery_Wh", "Wh_per_km", "speed_rmse_mps",
               "torque_rmse_Nm", "torque_error_max_Nm", "copper_loss_Wh", "iron_loss_Wh", "inverter_loss_Wh",
               "drive_loss_Wh", "w_m_peak_rpm", "time_above_top_speed_s", "steps", "wall_s", "real_time_factor")
#: ... and with the thermal network on
THERMAL_PRINTED = ("theta_winding_max_K", "theta_magnet_max_K", "theta_winding_end_K", "theta_magnet_end_K",
                   "heat_coolant_Wh", "heat_balance_residual_Wh", "time_derated_s", "derating_min")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m scenarios", description=__doc__)
    ap.add_argument("--version", action="version", version=f"ipmsm-fmu {VERSION}")
    ap.add_argument("--build", type=Path, default=BUILD_DIR, help="build folder with fmu/ (and ssp/); default: "
                    "the repository's build/, or the installed wheel's copies")
    sub = ap.add_subparsers(dest="cmd", required=True)

    sw = sub.add_parser("sweep", help="torque-speed sweep of the controller: table and plot of the optimal currents")
    sw.add_argument("--out", type=Path, default=OUT_DIR / "sweep")
    sw.add_argument("--recursion", type=int, default=2, choices=(0, 1, 2))
    sw.add_argument("--u-dc", type=float, default=None, help="V; default: the drive's controller.lut_u_dc")
    sw.add_argument("--drive", type=Path, default=None, help=DRIVE_HELP)

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
                          "model 30 %% off (needs --backend fmpy, where the two can differ); default 1")
    run.add_argument("--backend", default="drive", choices=BACKENDS,
                     help="drive: the IpmsmDrive FMU stepped at the vehicle's 10 ms (the fast path); fmpy: the "
                          "reference loop, IpmsmController and IpmsmPlant coupled at 100 us in Python (slow)")
    run.add_argument("--u-dc-scale", type=float, default=1.0, help="DC voltage seen by the drive / battery's")
    run.add_argument("--magnet-degC", type=float, default=T_REFERENCE_K - ZERO_CELSIUS_K)
    run.add_argument("--repeat", type=int, default=1, help="drive the cycle this many times in a row (thermal "
                     "runs: repeated US06, a motorway phase); default 1")
    run.add_argument("--out", type=Path, default=None)

    cmp_ = sub.add_parser("compare", help="Ferrari versus 2-D tables over cycles and conditions: report.md")
    cmp_.add_argument("--cycles", nargs="+", default=["WLTC3b"])
    cmp_.add_argument("--out", type=Path, default=OUT_DIR / "compare")
    cmp_.add_argument("--workers", type=int, default=None)
    cmp_.add_argument("--scheduler", default=None, help="an existing dask scheduler (as for study)")
    cmp_.add_argument("--drive", type=Path, default=None, help=DRIVE_HELP)
    fp = sub.add_parser("fmu-path", help="where the FMUs (and the SSP package) are: print the file's path")
    fp.add_argument("name", choices=FMU_NAMES + (SSP_NAME,), help="an FMU's model identifier, or the SSP package")
    from scenarios.runs import check
    check.add_parser(sub)
    map_cli.add_parser(sub)
    from scenarios.study import cli as study_cli
    study_cli.add_parser(sub)
    args = ap.parse_args(argv)
    from scenarios.core.boundary import InputError, printable
    from scenarios.maps.error import MapImportError
    try:
        return _dispatch(args)
    except (InputError, MapImportError) as e:  # the one boundary: file, key or line, what was expected
        print(f"error: {printable(str(e), limit=2000)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except OSError as e:  # an output that could not be written, a file that vanished
        print(f"error: {printable(str(e.filename or ''))}: {e.strerror or e}", file=sys.stderr)
        return EXIT_FAILED
    except Exception as e:  # a run that failed (an FMU refused, the battery ran flat): one line, no traceback
        print(f"error: {type(e).__name__}: {printable(str(e), limit=2000)}", file=sys.stderr)
        return EXIT_FAILED


def _slug(text: str) -> str:
    """A file-name part of `text`: letters, digits, '.', '-' and '_' only (a drive named
    x/../../evil stays one name inside out/)."""
    s = re.sub(r"_{2,}", "_", re.sub(r"[^A-Za-z0-9._-]+", "_", re.sub(r"\.{2,}", "_", text))).strip("._") or "run"
    return s[:100]


def _number_as_key(value: float | None, option: str, key: str) -> None:
    """A command-line number checked by a drive-description key's rule (None: not given)."""
    from scenarios.core.boundary import InputError
    from scenarios.drives.description import SCHEMA
    if value is None:
        return
    bad = next(k.rule for k in SCHEMA if k.path == key).check(value)
    if bad:
        raise InputError("(command line)", option, bad + ("" if "got" in bad else f", got {value!r}"))


def _cycle_arg(name: str, option: str):
    """A cycle named on the command line, loaded (a missing or malformed one: exit 2)."""
    from scenarios.core.boundary import InputError
    from scenarios.vehicle.cycles import load_cycle
    try:
        return load_cycle(name)
    except InputError:
        raise
    except (OSError, ValueError) as e:
        raise InputError("(command line)", option, f"a standard cycle or a CSV of time_s,speed_mps ({e})") from None


def _objective_arg(objective: str | None, drive) -> str:
    """--objective (None: the drive's); least loss only with FMUs that have it (else exit 2)."""
    from scenarios.core.boundary import InputError
    from scenarios.drives.description import OBJECTIVE_DEFAULT, controller_has_objective
    objective = objective or drive.controller.objective
    if objective != OBJECTIVE_DEFAULT and not controller_has_objective():
        raise InputError("(command line)", "--objective", "a value the built FMUs have: rebuild them (their model "
                         "descriptions have no `objective` parameter)")
    return objective


def _run_args(args) -> None:
    """run's numbers, refused (exit 2) before anything runs."""
    from scenarios.core.boundary import InputError, finite
    from scenarios.core.fmu_ranges import fmu_ranges
    finite(args.u_dc_scale, "(command line)", "--u-dc-scale", 0.0, U_DC_SCALE_MAX, lo_open=True)
    r = fmu_ranges()["T_magnet_ref"]  # the FMUs' temperature range
    finite(args.magnet_degC, "(command line)", "--magnet-degC", r.lo - ZERO_CELSIUS_K, r.hi - ZERO_CELSIUS_K)
    from scenarios.runs.simulate import CONTROLLER_LOSS_SCALE_MAX
    finite(args.controller_loss_scale, "(command line)", "--controller-loss-scale", 0.0, CONTROLLER_LOSS_SCALE_MAX,
           lo_open=True)
    if args.controller_loss_scale != 1.0 and args.backend != "fmpy":
        raise InputError("(command line)", "--controller-loss-scale", "--backend fmpy (IpmsmDrive declares the loss "
                         "parameters once for the controller and the plant)")
    if not 1 <= args.repeat <= REPEAT_MAX:
        raise InputError("(command line)", "--repeat", f"an integer in [1, {REPEAT_MAX}], got {args.repeat}")


def _dispatch(args) -> int:
    if args.cmd == "fmu-path":
        path = (args.build / "ssp" / f"{SSP_NAME}.ssp" if args.name == SSP_NAME
                else args.build / "fmu" / f"{args.name}.fmu")
        if not path.is_file():
            print(f"error: {path} is missing: build it (cmake --build build)", file=sys.stderr)
            return 2
        print(path)
        return 0
    from scenarios.core.boundary import check_writable, inside
    from scenarios.drives.description import load_drive as load_description
    from scenarios.drives.fmu_acceptance import refuse_unless_fmus_accept

    def load_drive(path):
        """The drive description, refused (exit 2) unless the FMUs accept its map and motor."""
        drive = load_description(path)
        refuse_unless_fmus_accept(drive, args.build)
        return drive

    if args.cmd == "check":
        from scenarios.runs import check
        return check.main(args)
    if args.cmd == "sweep":
        from scenarios.runs.sweep import SweepSpec, run_sweep
        _number_as_key(args.u_dc, "--u-dc", "controller.lut_u_dc")
        drive = load_drive(args.drive)
        check_writable(args.out)
        s = run_sweep(args.build / "fmu" / "IpmsmController.fmu", args.out,
                      SweepSpec(drive=drive, recursion=args.recursion, u_dc=args.u_dc))
        print(json.dumps({k: s.to_dict()[k] for k in ("points", "wall_s", "T_max_Nm_by_speed_rpm")}, indent=1))
        print(f"wrote {args.out}/sweep.csv, summary.json, current_trajectories.png")
    elif args.cmd == "run":
        from scenarios.core.boundary import InputError
        from scenarios.runs.plots import plot_run
        from scenarios.runs.simulate import Conditions, RunSpec, fmu_paths, simulate
        from scenarios.vehicle.cycles import repeated
        _run_args(args)
        drive = load_drive(args.drive)
        method = args.method or drive.controller.method
        objective = _objective_arg(args.objective, drive)
        T = args.magnet_degC + ZERO_CELSIUS_K
        custom = (args.u_dc_scale, T) != (1.0, T_REFERENCE_K)
        cond = Conditions("custom" if custom else "nominal", u_dc_scale=args.u_dc_scale, T_magnet=T, T_winding=T)
        cycle = _cycle_arg(args.cycle, "cycle")
        try:
            cycle = repeated(cycle, args.repeat)
        except ValueError as e:
            raise InputError("(command line)", "--repeat", str(e)) from None
        stem = Path(args.cycle).stem + ("" if args.repeat == 1 else f"_x{args.repeat}") + (
            "" if args.drive is None else f"_{drive.name}")
        stem += "" if objective == "current" else f"_least_{objective}"
        out = args.out or inside(OUT_DIR, _slug(f"{stem}_{method}"), "run's output folder")
        check_writable(out)
        s = simulate(cycle, RunSpec(drive=drive, method=method, recursion=args.recursion, conditions=cond,
                                    backend=args.backend, objective=objective,
                                    controller_loss_scale=args.controller_loss_scale),
                     fmus=fmu_paths(args.build), out=out)
        title = f"{s.cycle}, {method}" + ("" if objective == "current" else f", least {objective}") + (
            "" if args.drive is None else f", {drive.name}")
        plot_run(out, title, drive)
        if s.thermal_network:
            from scenarios.runs.thermal_plots import plot_thermal
            plot_thermal(out, title, drive.thermal.T_coolant)
        for a in drive.assumed:
            print(f"assumed: {a}", file=sys.stderr)
        d = s.to_dict()
        print(json.dumps({k: d[k] for k in RUN_PRINTED + (THERMAL_PRINTED if s.thermal_network else ())}, indent=1))
        print(f"wrote {out}/summary.json, trace.csv, run.png" + (", thermal.png" if s.thermal_network else ""))
    elif args.cmd == "compare":
        from scenarios.study.compare import run_study
        load_drive(args.drive)  # a bad description: exit 2 here, not one failed run per variant
        for c in args.cycles:
            _cycle_arg(c, "--cycles")
        check_writable(args.out)
        run_study(args.out, cycles=tuple(args.cycles), build=args.build, workers=args.workers,
                  scheduler=args.scheduler, drive=args.drive)
        print(f"wrote {args.out}/report.md, summary.csv, summary.json, study.png, runs/")
    elif args.cmd == "map":
        if args.map_cmd == "show" and args.drive is None:
            # the map's machine and the options as a drive's would be: the schema's rules (check and
            # repair read maps with holes and defects, which is their job: their options only)
            from scenarios.drives.description import check_map_machine
            check_map_machine(args.file, args.u_dc, args.I_max)
        elif args.map_cmd in ("show", "check", "repair"):
            _number_as_key(getattr(args, "u_dc", None), "--u-dc", "controller.lut_u_dc")
            _number_as_key(args.I_max, "--I-max", "motor.I_max")
        args.drive_description = load_drive(args.drive) if getattr(args, "drive", None) is not None else None
        return map_cli.main(args)
    elif args.cmd == "study":
        from scenarios.study import cli as study_cli
        return study_cli.main(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
