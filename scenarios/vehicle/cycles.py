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
from collections.abc import Sequence
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

    @property
    def moving_s(self) -> float:
        """Time the trace is not standing (either end of a sample interval above 0), s."""
        moving = (self.speed_mps[:-1] > 0.0) | (self.speed_mps[1:] > 0.0)
        return float(np.sum(np.diff(self.time_s)[moving]))

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


#: a cycle file of more bytes than this is no drive cycle: a week at 10 Hz is 6 million rows,
#: about 90 MB; a longer trace is a unit error (or an attack), refused before it is read
CYCLE_MAX_BYTES = 128 << 20
#: the longest cycle a run drives: a week; the vehicle side steps at 10 ms, and even streamed a
#: longer run is hours of computing for one command
CYCLE_MAX_DURATION_S = 7 * 86_400.0
#: the shortest: one second, the schedules' own resolution (they give the speed at whole seconds)
CYCLE_MIN_DURATION_S = 1.0
#: characters a line: two numbers and a comment never need more
CYCLE_MAX_LINE = 1024


def read_cycle_csv(path: str | Path, name: str | None = None) -> Cycle:
    """Read a `time_s,speed_mps` CSV strictly: the header first (blank lines and '#' comment
    lines are skipped), two finite numbers per row, time strictly increasing, 0 <= speed
    <= SPEED_PLAUSIBLE_MAX, at least two rows, a duration in [CYCLE_MIN_DURATION_S,
    CYCLE_MAX_DURATION_S], a regular UTF-8 file of at most CYCLE_MAX_BYTES. Errors
    (scenarios.core.boundary.InputError, a ValueError) name the file and the line."""
    from scenarios.core.boundary import InputError, decode_utf8, read_bounded
    path = Path(path)
    try:
        exists = path.exists()
    except (OSError, ValueError):
        exists = False
    if not exists:
        raise FileNotFoundError(f"cycle file not found: {path}")
    text = decode_utf8(path, read_bounded(path, CYCLE_MAX_BYTES, "drive cycle (CSV)"), "drive cycle (CSV)")
    times, speeds = [], []
    header_seen = False
    for lineno, line in enumerate(text.splitlines(), 1):
        if len(line) > CYCLE_MAX_LINE:
            raise InputError(path, f"line {lineno}", f"at most {CYCLE_MAX_LINE} characters, it has {len(line)}")
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in s.split(",")]
        if not header_seen:
            if tuple(cells) != HEADER:
                raise InputError(path, f"line {lineno}", f"the header 'time_s,speed_mps', got {s[:80]!r}")
            header_seen = True
            continue
        if len(cells) != 2:
            raise InputError(path, f"line {lineno}", f"2 columns, got {len(cells)}: {s[:80]!r}")
        try:
            t, v = float(cells[0]), float(cells[1])
        except ValueError:
            raise InputError(path, f"line {lineno}", f"two numbers, got {s[:80]!r}") from None
        if not (math.isfinite(t) and math.isfinite(v)):
            raise InputError(path, f"line {lineno}", f"finite numbers, got NaN or Inf: {s[:80]!r}")
        if v < 0.0:
            raise InputError(path, f"line {lineno}", f"a speed >= 0 m/s, got {v} (reverse driving is not modelled)")
        if v > SPEED_PLAUSIBLE_MAX:
            raise InputError(path, f"line {lineno}", f"a speed <= {SPEED_PLAUSIBLE_MAX} m/s, got {v}: is the "
                             f"column in km/h or mph? It must be m/s")
        if times and t <= times[-1]:
            raise InputError(path, f"line {lineno}", f"time increasing, got {t} s after {times[-1]} s")
        if times and t - times[0] > CYCLE_MAX_DURATION_S:
            raise InputError(path, f"line {lineno}", f"a cycle of at most {CYCLE_MAX_DURATION_S:g} s, time {t} s "
                             f"is {t - times[0]:g} s after the start")
        times.append(t)
        speeds.append(v)
    if not header_seen:
        raise InputError(path, "(file)", "the header 'time_s,speed_mps' (the file is empty)")
    if len(times) < 2:
        raise InputError(path, "(file)", f"at least 2 samples, got {len(times)}")
    if times[-1] - times[0] < CYCLE_MIN_DURATION_S:
        raise InputError(path, "(file)", f"a cycle of at least {CYCLE_MIN_DURATION_S:g} s, got "
                         f"{times[-1] - times[0]:g} s")
    return Cycle(name or path.stem, np.array(times), np.array(speeds))


def load_cycle(name_or_path: str | Path) -> Cycle:
    """A standard cycle by name (WLTC3b, UDDS, HWFET, US06, NEDC; case-insensitive) or any
    CSV with a `time_s,speed_mps` header. Unpacks as (time_s, speed_mps)."""
    name, path = _resolve(name_or_path)
    return read_cycle_csv(path, name)


class _Sampled(Sequence):
    """t0 + k dt (times) or the cycle's speed there (speeds), k = 0..n, computed a block at a
    time when indexed: the vehicle loop reads them in order, and a week-long cycle at 10 ms
    (60 million samples) never sits in memory."""

    BLOCK = 1 << 16

    def __init__(self, cycle: Cycle, dt: float, n: int, speeds: bool):
        self._cycle, self._dt, self._n, self._speeds = cycle, dt, n, speeds
        self._start, self._block = -1, None

    def __len__(self) -> int:
        return self._n + 1

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        if k < 0:
            k += len(self)
        if not 0 <= k < len(self):
            raise IndexError(k)
        start = k - k % self.BLOCK
        if start != self._start:
            t = self._cycle.time_s[0] + self._dt * np.arange(start, min(start + self.BLOCK, len(self)))
            self._block = (self._cycle.speed_at(t) if self._speeds else t).tolist()
            self._start = start
        return self._block[k - start]


def sampled(cycle: Cycle, dt: float, n: int) -> tuple[Sequence[float], Sequence[float]]:
    """The times t0 + k dt and the cycle's speeds at them, k = 0..n, as lazy sequences."""
    return _Sampled(cycle, dt, n, False), _Sampled(cycle, dt, n, True)


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


def repeated(cycle: Cycle, n: int) -> Cycle:
    """`cycle` driven n times in a row (each copy starts where the one before ended), named
    "<name> x<n>". The cycle must end at the speed it starts at (a standard cycle's standstill)."""
    if n < 1:
        raise ValueError(f"a cycle is repeated at least once, got {n}")
    if n * cycle.duration_s > CYCLE_MAX_DURATION_S:  # before any copy is made
        raise ValueError(f"{n} copies of {cycle.name}'s {cycle.duration_s:g} s are {n * cycle.duration_s:g} s, past "
                         f"the longest run ({CYCLE_MAX_DURATION_S:g} s, a week)")
    if n == 1:
        return cycle
    t, v = cycle.time_s - cycle.time_s[0], cycle.speed_mps
    if v[-1] != v[0]:
        raise ValueError(f"{cycle.name} ends at {v[-1]:g} m/s, not at its start's {v[0]:g} m/s: its copies "
                         "would not join")
    ts = np.concatenate([t] + [t[1:] + k * t[-1] for k in range(1, n)]) + cycle.time_s[0]
    vs = np.concatenate([v] + [v[1:]] * (n - 1))
    return Cycle(f"{cycle.name} x{n}", ts, vs)
