"""Least loss against least current on the standard cycles: the battery energy saved and the
loss split (copper, iron, inverter) per drive and cycle, as docs/least_loss.md tabulates it.

    python -m tools.least_loss_cycles                       # UDDS, HWFET, US06, WLTC3b x default, city
    python -m tools.least_loss_cycles --cycles UDDS --drives scenarios/drives/default.toml --workers 1

Every pair of runs is a study (scenarios.study: runs.parquet in --out, resumable, a local Dask
cluster of --workers processes) with the axis `objectives = ["current", "loss"]`: the same drive,
cycle, driver and conditions (nominal), so both drive the same cycle; the distance of each is in
the table (the driver follows the cycle within centimetres, so "saved" is at the same distance).
Prints the Markdown table and writes it to OUT/least_loss.md.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from scenarios.core.paths import OUT_DIR
from scenarios.drives.description import DRIVES_DIR, controller_has_objective
from scenarios.study import run_study
from scenarios.study.spec import Run

CYCLES = ("UDDS", "HWFET", "US06", "WLTC3b")
DRIVES = (DRIVES_DIR / "default.toml", DRIVES_DIR / "city_ev.toml")
OBJECTIVES = ("current", "loss")


def runs(drives, cycles) -> list[Run]:
    return [Run(drive=str(Path(d).resolve()), cycle=c, objective=o) for d in drives for c in cycles
            for o in OBJECTIVES]


def table(rows: list[dict]) -> str:
    """The Markdown table of a study's rows: one line per drive and cycle."""
    by = {(r["drive"], r["cycle"], r["objective"]): r for r in rows if r["status"] == "ok"}
    lines = ["| drive | cycle | km (current / loss) | battery Wh: least current | least loss | saved Wh | saved % "
             "| copper Wh (current → loss) | iron Wh | inverter Wh | drive loss Wh | Wh/km saved |",
             "|---|---|---|---:|---:|---:|---:|---|---|---|---|---:|"]
    for (drive, cycle, objective), a in by.items():
        if objective != "current" or (drive, cycle, "loss") not in by:
            continue
        b = by[(drive, cycle, "loss")]
        saved = a["energy_battery_Wh"] - b["energy_battery_Wh"]
        lines.append(
            f"| {a['drive_name']} | {cycle} | {a['distance_km']:.3f} / {b['distance_km']:.3f} | "
            f"{a['energy_battery_Wh']:.1f} | {b['energy_battery_Wh']:.1f} | {saved:.1f} | "
            f"{100 * saved / a['energy_battery_Wh']:.2f} | "
            f"{a['copper_loss_Wh']:.1f} → {b['copper_loss_Wh']:.1f} | "
            f"{a['iron_loss_Wh']:.1f} → {b['iron_loss_Wh']:.1f} | "
            f"{a['inverter_loss_Wh']:.1f} → {b['inverter_loss_Wh']:.1f} | "
            f"{a['drive_loss_Wh']:.1f} → {b['drive_loss_Wh']:.1f} | {a['Wh_per_km'] - b['Wh_per_km']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycles", nargs="+", default=list(CYCLES))
    ap.add_argument("--drives", nargs="+", type=Path, default=list(DRIVES))
    ap.add_argument("--out", type=Path, default=OUT_DIR / "least_loss_cycles")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    if not controller_has_objective():
        print("least_loss_cycles: the built FMUs have no `objective` parameter: rebuild them", file=sys.stderr)
        return 2
    result = run_study(runs(args.drives, args.cycles), args.out, workers=args.workers)
    rows = [r for r in result.table.to_pylist() if r["key"] in set(result.keys)]
    failed = [r for r in rows if r["status"] != "ok"]
    text = table(rows)
    (args.out / "least_loss.md").write_text(text + "\n")
    print(text)
    for r in failed:
        print(f"failed: {r['drive']} {r['cycle']} {r['objective']}: {r['error']}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
