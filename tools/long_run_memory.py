"""Peak memory of a long drive-cycle run, end to end: `python -m scenarios run` on UDDS repeated
for HOURS of simulated time, measured by /usr/bin/time -v (peak resident set size).

    python tools/long_run_memory.py 168 --work /tmp/week     # a week: 442 UDDS back to back
    python tools/long_run_memory.py 1 4                      # 1 h and 4 h: does memory grow?

The drive is the default EV with a battery of 100 times its cells' capacity (a week of UDDS is
5300 km; the default pack would run flat after some 300 km, which ends a run): the memory of the
run is what is measured, not the pack. Prints one line per run: hours, trace rows, wall time
and peak RSS (MiB); --json adds them as JSON lines.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from pathlib import Path

from scenarios.core.paths import DATA_DIR
from scenarios.maps.flux_map import DEFAULT_MAP
from scenarios.vehicle.battery import BatteryParams

UDDS = DATA_DIR / "cycles" / "UDDS.csv"
#: the pack's capacity scale: a week of UDDS on the default pack's state of charge barely moves
CAPACITY_SCALE = 100.0


def repeated_cycle(path: Path, hours: float) -> Path:
    """UDDS back to back (each repeat starting where the last ended) up to `hours`, as a cycle CSV
    streamed to `path` (a week is 605 000 rows)."""
    rows = [line.split(",") for line in UDDS.read_text().splitlines()[1:] if line.strip()]
    t = [float(a) for a, _ in rows]
    v = [b.strip() for _, b in rows]
    period, end = t[-1], hours * 3600.0
    with open(path, "w") as f:
        f.write("time_s,speed_mps\n")
        offset, first = 0.0, True
        while offset < end:
            for k, (tk, vk) in enumerate(zip(t, v)):
                if k == 0 and not first:
                    continue  # the repeat's first row is the last one's end
                if offset + tk > end:
                    break
                f.write(f"{offset + tk:g},{vk}\n")
            offset += period
            first = False
    return path


def drive_file(path: Path) -> Path:
    path.write_text(f'name = "long_run"\n[motor]\nflux_map = "{DEFAULT_MAP}"\n[battery]\n'
                    f"cell_capacity_Ah = {BatteryParams().cell_capacity_Ah * CAPACITY_SCALE:g}\n")
    return path


def measure(hours: float, work: Path) -> dict:
    work.mkdir(parents=True, exist_ok=True)
    cycle = repeated_cycle(work / f"udds_{hours:g}h.csv", hours)
    drive = drive_file(work / "long_run.toml")
    out = work / f"run_{hours:g}h"
    t0 = time.perf_counter()
    r = subprocess.run(["/usr/bin/time", "-v", sys.executable, "-m", "scenarios", "run", str(cycle), "--drive",
                        str(drive), "--out", str(out)], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"run of {hours:g} h failed (exit {r.returncode}):\n{r.stderr[-3000:]}")
    rss_kib = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr).group(1))
    with open(out / "trace.csv", "rb") as f:
        trace_rows = sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(1 << 20), b"")) - 1
    return dict(hours=hours, trace_rows=trace_rows, wall_s=round(wall, 1), peak_rss_MiB=round(rss_kib / 1024, 1),
                trace_MiB=round((out / "trace.csv").stat().st_size / 2**20, 1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("hours", type=float, nargs="+", help="simulated hours of each run")
    ap.add_argument("--work", type=Path, default=Path("out/long_run_memory"), help="folder for cycles and runs")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    for h in args.hours:
        m = measure(h, args.work)
        print(f"{m['hours']:g} h: {m['trace_rows']} trace rows ({m['trace_MiB']} MiB), wall {m['wall_s']} s, "
              f"peak RSS {m['peak_rss_MiB']} MiB")
        if args.json:
            print(json.dumps(m))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
