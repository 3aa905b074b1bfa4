"""Benchmark (issue 27): the cost of the machine's thermal network in a whole run. A full WLTC 3b
through the IpmsmDrive FMU with the network off and on (scenarios/drives/default.toml and the
same drive with `[thermal] thermal_model = true`, scenarios/drives/thermal.toml's boundary),
alternating off, on, off, on, ... so that a drift of the machine's load hits both alike; the
median of each and their ratio. Target: on at most 5 % slower than off.

    .venv/bin/python bench/bench_thermal_drive.py [--repeats 3] [--cycle WLTC3b] [--until SECONDS]
                                                   [--mode replay|run]

--mode replay (default): the drive's inputs of one whole run are recorded once (the vehicle side
at 10 ms, the network off), then replayed into a fresh IpmsmDrive per repetition: the timed loop
is the FMU's fmi2SetReal, fmi2DoStep and output reads alone, where the network's cost shows
undiluted. --mode run: whole `simulate` runs (vehicle side, accounts, trace; no reference
optimum), what a user waits for.
"""
from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import replace

from scenarios.cosim.drive_fmu import DriveFmu
from scenarios.drives.description import DRIVES_DIR, load_drive
from scenarios.runs.simulate import RunSpec, fmu_paths, simulate
from scenarios.vehicle.cycles import load_cycle, segment


def drives():
    """The default drive (off) and the same with the network on and thermal.toml's boundary."""
    off, thermal = load_drive(None), load_drive(DRIVES_DIR / "thermal.toml")
    return off, replace(off, thermal=thermal.thermal)


def record(cycle, drive):
    """(T_ref, w_m, u_dc, T_magnet, T_winding) of each vehicle step of a run."""
    rows = []
    simulate(cycle, RunSpec(drive=drive, reference=False), fmus=fmu_paths(), progress=False,
             observe=lambda s: rows.append((s.T_ref, s.w_m, s.u_dc)))
    return rows


def replay(drive, rows, spec: RunSpec) -> float:
    """Wall seconds of the drive's steps over the recorded inputs."""
    c, p = fmu_paths()
    t = drive.thermal
    boundary = dict(T_coolant=t.T_coolant, T_ambient=t.T_ambient) if t.on else {}
    params = {**drive.controller_params(), **drive.plant_params(), **t.fmu_params(),
              "sample_time": spec.h}
    T0 = spec.conditions.T_magnet
    with DriveFmu(c.parent / "IpmsmDrive.fmu", params, w_m=rows[0][1], u_dc=rows[0][2], T_magnet=T0, T_winding=T0,
                  **boundary) as fmu:
        t0 = time.perf_counter()
        for T_ref, w_m, u_dc in rows:
            fmu.advance(spec.dt, T_ref, w_m, u_dc, T0, T0)
        return time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cycle", default="WLTC3b")
    ap.add_argument("--until", type=float, default=None, help="s: only the cycle's first part")
    ap.add_argument("--repeats", type=int, default=3, help="runs of each, alternating")
    ap.add_argument("--mode", choices=("replay", "run"), default="replay")
    args = ap.parse_args(argv)
    cycle = load_cycle(args.cycle)
    if args.until is not None:
        cycle = segment(cycle, 0.0, args.until)
    off, on = drives()
    spec = RunSpec(reference=False)
    rows = record(cycle, off) if args.mode == "replay" else None
    times = {"off": [], "on": []}
    for _ in range(args.repeats):
        for name, drive in (("off", off), ("on", on)):
            if args.mode == "replay":
                times[name].append(replay(drive, rows, spec))
            else:
                t0 = time.perf_counter()
                simulate(cycle, replace(spec, drive=drive), fmus=fmu_paths(), progress=False)
                times[name].append(time.perf_counter() - t0)
            print(f"{name}: {times[name][-1]:.2f} s", flush=True)
    med = {k: statistics.median(v) for k, v in times.items()}
    print(f"{cycle.name}, {args.mode}, {args.repeats} alternating runs each: median off {med['off']:.2f} s, "
          f"on {med['on']:.2f} s, on/off {med['on'] / med['off'] - 1:+.1%} (target <= +5 %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
