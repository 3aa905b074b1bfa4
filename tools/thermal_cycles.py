"""Writes the thermal scenarios' speed traces, scenarios/data/cycles/thermal/ (SOURCES.md there
says what each is):

    python tools/thermal_cycles.py

- WLTC3b_extra_high.csv: the WLTC class 3b's Extra High 3 phase (UN GTR 15, Annex 1: t = 1477 to
  1800 s of the class 3b table, standstill at both ends), cut from scenarios/data/cycles/WLTC3b.csv
  and re-based to t = 0; `run ... --repeat N` drives it N times: a long motorway run.
- climb_150kmh.csv: a full-power climb's request: 0 to 150 km/h in CLIMB_RAMP_S, held to
  CLIMB_DURATION_S. With the drive's `[vehicle] grade` (scenarios/drives/thermal_climb.toml: 10 %)
  the car cannot reach 150 km/h, so the driver asks for the whole torque limit all along and the
  drive runs at its power limit for the whole climb.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from scenarios.core.paths import DATA_DIR
from scenarios.vehicle.cycles import load_cycle, segment

OUT = DATA_DIR / "cycles" / "thermal"
#: s, the Extra High 3 phase of the WLTC class 3b (UN GTR 15, Annex 1, Table A1/12)
EXTRA_HIGH_S = (1477.0, 1800.0)
KMH = 1 / 3.6
CLIMB_SPEED = 150.0 * KMH   # m/s, beyond what the default EV reaches on a 10 % grade (about 145 km/h)
CLIMB_RAMP_S = 30.0          # s, 0 to 150 km/h: 1.39 m/s^2, within the WLTC's 1.67 m/s^2
CLIMB_DURATION_S = 900.0     # s, 15 minutes: several of the winding's time constants (docs/thermal.md)


def write(path: Path, t, v) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("time_s", "speed_mps"))
        w.writerows((f"{a:g}", repr(float(b))) for a, b in zip(t, v))


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    xh = segment(load_cycle("WLTC3b"), *EXTRA_HIGH_S)
    write(OUT / "WLTC3b_extra_high.csv", xh.time_s, xh.speed_mps)
    t = np.arange(0.0, CLIMB_DURATION_S + 1.0)
    write(OUT / "climb_150kmh.csv", t, np.minimum(t / CLIMB_RAMP_S, 1.0) * CLIMB_SPEED)


if __name__ == "__main__":
    main()
