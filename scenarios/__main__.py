"""Command line: python -m scenarios sweep [--out DIR] ..."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m scenarios", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    sw = sub.add_parser("sweep", help="torque-speed sweep of the controller: table and plot of the optimal currents")
    sw.add_argument("--out", type=Path, default=ROOT / "out" / "sweep")
    sw.add_argument("--fmu", type=Path, default=ROOT / "build" / "fmu" / "IpmsmController.fmu")
    sw.add_argument("--recursion", type=int, default=2, choices=(0, 1, 2))
    sw.add_argument("--u-dc", type=float, default=355.0)
    args = ap.parse_args(argv)
    if args.cmd == "sweep":
        from .sweep import SweepSpec, run_sweep
        s = run_sweep(args.fmu, args.out, SweepSpec(recursion=args.recursion, u_dc=args.u_dc))
        print(json.dumps({k: s[k] for k in ("points", "wall_s", "T_max_Nm_by_speed_rpm")}, indent=1))
        print(f"wrote {args.out}/sweep.csv, summary.json, current_trajectories.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
