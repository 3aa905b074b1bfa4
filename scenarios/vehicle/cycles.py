"""Drive cycles: speed traces `time_s,speed_mps` (SI), the standard ones shipped in
`scenarios/data/cycles/` (sources and verified statistics in its SOURCES.md) or any
user CSV in the same format.

    >>> t, v = load_cycle("udds")            # unpacks as (time_s, speed_mps)
    >>> c = load_cycle("my_trace.csv"); c.distance_m, c.duration_s
    >>> seg = segment(c, 100.0, 400.0)       # a piece, re-based to start at t = 0

The vehicle side samples the trace at its own step (10 ms) by linear interpolation between
the 1 Hz points, the usual reading of a schedule (GTR 15 and the EPA schedules specify the
speed at whole seconds and the driver follows the straight line between them).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenarios.core.paths import DATA_DIR

#: where the standard cycles live: the package's data/cycles/ (scenarios.core.paths.DATA_DIR)
CYCLES_DIR = DATA_DIR / "cycles"

#: canonical names (matched case-insensitively) -> file in CYCLES_DIR
STANDARD_CYCLES = {
    "WLTC3b": "WLTC3b.csv",  # UN GTR 15 WLTC class 3b
    "UDDS": "UDDS.csv",      # EPA urban (FTP-72 / LA-4)
    "HWFET": "HWFET.csv",    # EPA highway
    "US06": "US06.csv",      # EPA SFTP aggressive
    "NEDC": "NEDC.csv",      # UN ECE R83/R101, 4 x ECE-15 + EUDC
}

HEADER = ("time_s", "speed_mps")

#: a trace faster than this is almost surely in km/h or mph, not m/s (the fastest standard
#: cycle, WLTC 3b, peaks at 36.5 m/s; 100 m/s = 360 km/h)
SPEED_PLAUSIBLE_MAX = 100.0  # m/s


@dataclass(frozen=True)
class Cycle:
    """A speed trace: strictly increasing time (s), speed >= 0 (m/s)."""

    name: str
    time_s: np.ndarray
    speed_mps: np.ndarray

    def __iter__(self):
        # lets `t, v = load_cycle(...)` work
        yield self.time_s
        yield self.speed_mps

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def distance_m(self) -> float:
        """Trapezoidal integral of the samples (as in SOURCES.md)."""
        return float(np.trapezoid(self.speed_mps, self.time_s))

    def speed_at(self, t):
        """Reference speed at time(s) t, linear between samples, held outside the trace."""
        return np.interp(t, self.time_s, self.speed_mps)

    def stats(self) -> dict:
        return cycle_stats(self)


def _resolve(name_or_path: str | Path) -> tuple[str, Path]:
    s = str(name_or_path)
    for name, file in STANDARD_CYCLES.items():
        if s.lower() == name.lower():
            return name, CYCLES_DIR / file
    p = Path(s)
    if p.suffix.lower() != ".csv" and not p.exists():
        raise ValueError(f"unknown cycle {s!r}: use one of {', '.join(STANDARD_CYCLES)} "
                         f"(case-insensitive) or the path of a CSV with header time_s,speed_mps")
    return p.stem, p


def read_cycle_csv(path: str | Path, name: str | None = None) -> Cycle:
    """Read a `time_s,speed_mps` CSV strictly: the header first (blank lines and '#' comment
    lines are skipped), two finite numbers per row, time strictly increasing, 0 <= speed
    <= SPEED_PLAUSIBLE_MAX, at least two rows. Errors name the file and the line."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"cycle file not found: {path}")
    rows = []
    header_seen = False
    with open(path, newline="") as f:
        for lineno, line in enumerate(f, 1):
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            cells = [c.strip() for c in s.split(",")]
            if not header_seen:
                if tuple(cells) != HEADER:
                    raise ValueError(f"{path}:{lineno}: expected header 'time_s,speed_mps', got {s!r}")
                header_seen = True
                continue
            if len(cells) != 2:
                raise ValueError(f"{path}:{lineno}: expected 2 columns, got {len(cells)}: {s!r}")
            try:
                t, v = float(cells[0]), float(cells[1])
            except ValueError:
                raise ValueError(f"{path}:{lineno}: not a number: {s!r}") from None
            if not (math.isfinite(t) and math.isfinite(v)):
                raise ValueError(f"{path}:{lineno}: NaN or Inf: {s!r}")
            if v < 0.0:
                raise ValueError(f"{path}:{lineno}: negative speed {v} m/s (reverse driving is not modelled)")
            if v > SPEED_PLAUSIBLE_MAX:
                raise ValueError(f"{path}:{lineno}: speed {v} m/s > {SPEED_PLAUSIBLE_MAX} m/s: "
                                 f"is the column in km/h or mph? It must be m/s")
            if rows and t <= rows[-1][0]:
                raise ValueError(f"{path}:{lineno}: time {t} s does not increase (previous {rows[-1][0]} s)")
            rows.append((t, v))
    if not header_seen:
        raise ValueError(f"{path}: empty file (expected header 'time_s,speed_mps')")
    if len(rows) < 2:
        raise ValueError(f"{path}: needs at least 2 samples, got {len(rows)}")
    a = np.array(rows)
    return Cycle(name or path.stem, a[:, 0].copy(), a[:, 1].copy())


def load_cycle(name_or_path: str | Path) -> Cycle:
    """A standard cycle by name (WLTC3b, UDDS, HWFET, US06, NEDC; case-insensitive) or any
    CSV with a `time_s,speed_mps` header. Unpacks as (time_s, speed_mps)."""
    name, path = _resolve(name_or_path)
    return read_cycle_csv(path, name)


def segment(cycle: Cycle, t0: float, t1: float, rebase: bool = True) -> Cycle:
    """The part of `cycle` between t0 and t1 (s), end points interpolated if they fall between
    samples; with `rebase` time starts at 0."""
    t, v = cycle.time_s, cycle.speed_mps
    if not (t[0] <= t0 < t1 <= t[-1]):
        raise ValueError(f"segment [{t0}, {t1}] s is not inside {cycle.name} [{t[0]}, {t[-1]}] s")
    inner = (t > t0) & (t < t1)
    ts = np.concatenate(([t0], t[inner], [t1]))
    vs = np.concatenate(([np.interp(t0, t, v)], v[inner], [np.interp(t1, t, v)]))
    if rebase:
        ts = ts - t0
    return Cycle(f"{cycle.name}[{t0:g}:{t1:g}]", ts, vs)


def cycle_stats(cycle: Cycle) -> dict:
    """Distance, duration, speeds and accelerations (between samples), in SI units."""
    t, v = cycle.time_s, cycle.speed_mps
    a = np.diff(v) / np.diff(t)
    d = cycle.distance_m
    return dict(
        name=cycle.name,
        samples=len(t),
        duration_s=cycle.duration_s,
        distance_m=d,
        v_max_mps=float(v.max()),
        v_mean_mps=d / cycle.duration_s,
        a_max_mps2=float(a.max()),
        a_min_mps2=float(a.min()),
        stopped_fraction=float(np.sum(np.diff(t)[(v[:-1] == 0) & (v[1:] == 0)]) / cycle.duration_s),
    )
