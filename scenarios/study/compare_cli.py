"""python -m scenarios compare: Ferrari versus 2-D tables over cycles and conditions (the study
preset scenarios.study.compare): report.md, summary.csv, summary.json, study.png, runs/."""
from __future__ import annotations

from pathlib import Path

from scenarios.core.paths import OUT_DIR
from scenarios.runs.cli import DRIVE_HELP, cycle_arg


def add_parser(sub) -> None:
    p = sub.add_parser("compare", help="Ferrari versus 2-D tables over cycles and conditions: report.md")
    p.add_argument("--cycles", nargs="+", default=["WLTC3b"])
    p.add_argument("--out", type=Path, default=OUT_DIR / "compare")
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--scheduler", default=None, help="an existing dask scheduler (as for study)")
    p.add_argument("--drive", type=Path, default=None, help=DRIVE_HELP)


def main(args) -> int:
    from scenarios.core.boundary import check_writable
    from scenarios.drives.fmu_acceptance import load_accepted
    from scenarios.study.compare import run_study
    load_accepted(args.drive, args.build)  # a bad description: exit 2 here, not one failed run per variant
    for c in args.cycles:
        cycle_arg(c, "--cycles")
    check_writable(args.out)
    run_study(args.out, cycles=tuple(args.cycles), build=args.build, workers=args.workers,
              scheduler=args.scheduler, drive=args.drive)
    print(f"wrote {args.out}/report.md, summary.csv, summary.json, study.png, runs/")
    return 0
