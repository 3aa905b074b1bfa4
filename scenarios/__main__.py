"""python -m scenarios {sweep, run, compare, check, study, map, fmu-path} ... (see --help of each). A bad drive
description or input exits 2 with the file, the key and what was expected."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from scenarios.core.constants import T_REFERENCE_K, ZERO_CELSIUS_K
from scenarios.core.paths import BUILD_DIR, OUT_DIR
from scenarios.core.version import VERSION
from scenarios.cosim import BACKENDS
from scenarios.maps import cli as map_cli

#: the contract's summary keys (docs/spec/INTERFACE.md) and the real-time factor: what `run` prints
DRIVE_HELP = "drive description (TOML, docs/drives.md); default: scenarios/drives/default.toml"

#: what `fmu-path` finds: the FMUs (build/fmu/NAME.fmu) and the SSP package (build/ssp/NAME.ssp)
FMU_NAMES = ("IpmsmController", "IpmsmPlant", "IpmsmDrive")
SSP_NAME = "IpmsmControllerPlant"

RUN_PRINTED = ("cycle", "method", "distance_km", "energy_battery_Wh", "Wh_per_km", "speed_rmse_mps", "torque_rmse_Nm",
               "torque_error_max_Nm", "copper_loss_Wh", "iron_loss_Wh", "w_m_peak_rpm", "time_above_top_speed_s",
               "steps", "wall_s", "real_time_factor")


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
    run.add_argument("--backend", default="drive", choices=BACKENDS,
                     help="drive: the IpmsmDrive FMU stepped at the vehicle's 10 ms (the fast path); fmpy: the "
                          "reference loop, IpmsmController and IpmsmPlant coupled at 100 us in Python (slow)")
    run.add_argument("--u-dc-scale", type=float, default=1.0, help="DC voltage seen by the drive / battery's")
    run.add_argument("--magnet-degC", type=float, default=T_REFERENCE_K - ZERO_CELSIUS_K)
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
    from scenarios.drives.description import DriveDescriptionError
    try:
        return _dispatch(args)
    except DriveDescriptionError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


def _dispatch(args) -> int:
    if args.cmd == "fmu-path":
        path = (args.build / "ssp" / f"{SSP_NAME}.ssp" if args.name == SSP_NAME
                else args.build / "fmu" / f"{args.name}.fmu")
        if not path.is_file():
            print(f"error: {path} is missing: build it (cmake --build build)", file=sys.stderr)
            return 2
        print(path)
        return 0
    from scenarios.drives.description import load_drive
    if args.cmd == "check":
        from scenarios.runs import check
        return check.main(args)
    if args.cmd == "sweep":
        from scenarios.runs.sweep import SweepSpec, run_sweep
        drive = load_drive(args.drive)
        s = run_sweep(args.build / "fmu" / "IpmsmController.fmu", args.out,
                      SweepSpec(drive=drive, recursion=args.recursion, u_dc=args.u_dc))
        print(json.dumps({k: s.to_dict()[k] for k in ("points", "wall_s", "T_max_Nm_by_speed_rpm")}, indent=1))
        print(f"wrote {args.out}/sweep.csv, summary.json, current_trajectories.png")
    elif args.cmd == "run":
        from scenarios.runs.plots import plot_run
        from scenarios.runs.simulate import Conditions, RunSpec, fmu_paths, simulate
        drive = load_drive(args.drive)
        method = args.method or drive.controller.method
        T = args.magnet_degC + ZERO_CELSIUS_K
        custom = (args.u_dc_scale, T) != (1.0, T_REFERENCE_K)
        cond = Conditions("custom" if custom else "nominal", u_dc_scale=args.u_dc_scale, T_magnet=T, T_winding=T)
        stem = Path(args.cycle).stem + ("" if args.drive is None else f"_{drive.name}")
        out = args.out or OUT_DIR / f"{stem}_{method}"
        s = simulate(args.cycle, RunSpec(drive=drive, method=method, recursion=args.recursion, conditions=cond,
                                         backend=args.backend), fmus=fmu_paths(args.build), out=out)
        plot_run(out, f"{s.cycle}, {method}" + ("" if args.drive is None else f", {drive.name}"), drive)
        for a in drive.assumed:
            print(f"assumed: {a}", file=sys.stderr)
        d = s.to_dict()
        print(json.dumps({k: d[k] for k in RUN_PRINTED}, indent=1))
        print(f"wrote {out}/summary.json, trace.csv, run.png")
    elif args.cmd == "compare":
        from scenarios.study.compare import run_study
        load_drive(args.drive)  # a bad description: exit 2 here, not one failed run per variant
        run_study(args.out, cycles=tuple(args.cycles), build=args.build, workers=args.workers,
                  scheduler=args.scheduler, drive=args.drive)
        print(f"wrote {args.out}/report.md, summary.csv, summary.json, study.png, runs/")
    elif args.cmd == "map":
        args.drive_description = load_drive(args.drive) if getattr(args, "drive", None) is not None else None
        return map_cli.main(args)
    elif args.cmd == "study":
        from scenarios.study import cli as study_cli
        return study_cli.main(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
