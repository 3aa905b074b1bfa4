"""`python -m scenarios study SPEC.toml [--scheduler ADDRESS] [--out DIR] [--workers N]`, and
`python -m scenarios study --report-only DIR`. Exit status: 0 every run ok, 1 some run failed
(or the study could not run: no FMUs, no scheduler), 2 a bad specification."""
from __future__ import annotations

import sys
from pathlib import Path

from scenarios.core.paths import OUT_DIR


def add_parser(sub) -> None:
    p = sub.add_parser("study", help="a parameter study (TOML) on dask.distributed: DIR/runs.parquet, report.md")
    p.add_argument("spec", nargs="?", type=Path, help="the study specification (TOML)")
    p.add_argument("--scheduler", default=None,
                   help="address of an existing dask scheduler (tcp://host:8786); default: a local cluster")
    p.add_argument("--out", type=Path, default=None, help="the study's folder (default out/study/<spec's name>)")
    p.add_argument("--workers", type=int, default=None, help="local cluster: worker processes (default: the cores)")
    p.add_argument("--report-only", type=Path, default=None, metavar="DIR",
                   help="make DIR/report.md again from DIR/runs.parquet, without running")


def main(args) -> int:
    from scenarios.study import SpecError, StudyError, load_spec, run_study
    from scenarios.study.report import write_report
    from scenarios.study.table import consolidate

    if args.report_only:
        if not (args.report_only / "runs.parquet").exists() and not (args.report_only / "parts").is_dir():
            print(f"{args.report_only}: no runs.parquet", file=sys.stderr)
            return 2
        print(f"wrote {write_report(args.report_only, consolidate(args.report_only))}")
        return 0
    if args.spec is None:
        print("study: a specification (SPEC.toml) or --report-only DIR is needed", file=sys.stderr)
        return 2
    if args.workers is not None and args.workers < 1:
        print(f"study: --workers {args.workers}: must be >= 1", file=sys.stderr)
        return 2
    from scenarios.core.boundary import InputError, check_writable, printable
    from scenarios.study.runner import scheduler_address
    try:
        if args.scheduler is not None:
            scheduler_address(args.scheduler)
        spec = load_spec(args.spec)
        out = args.out or OUT_DIR / "study" / args.spec.stem
        check_writable(out)
    except (SpecError, InputError) as e:
        print(f"study: {printable(str(e), limit=2000)}", file=sys.stderr)
        return 2
    print(printable(f"study: {len(spec.runs)} runs of {args.spec} -> {out}"), flush=True)
    try:
        result = run_study(spec.runs, out, scheduler=args.scheduler, workers=args.workers, build=args.build)
    except StudyError as e:
        print(f"study: {e}", file=sys.stderr)
        return 1
    report = write_report(out, result.table)
    print(f"study: {result.executed} runs executed ({result.failed} failed), {result.skipped} done before; "
          f"wrote {out / 'runs.parquet'}, {report}", flush=True)
    return 1 if result.failed else 0
