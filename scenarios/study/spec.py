"""The study specification (docs/spec/INTERFACE.md, "Study specification (TOML)"): a TOML
file whose `[study]` table names the axes, each a list (a scalar is a list of one), whose
product is the set of runs; or an explicit list of runs (`[[run]]` tables, one key per axis,
singular: drive, cycle, method, ...), each missing key taking the default. `window_s` is one
[start, end] pair (s), not an axis: only that part of each cycle is driven.

    [study]
    drives = ["a.toml", "b.toml"]      # drive descriptions, relative to the spec; default: the default drive
    cycles = ["WLTC3b", "my.csv"]      # names or CSVs of time_s,speed_mps
    window_s = [0.0, 120.0]
    methods = ["ferrari", "lut_speed", "lut_flux"]
    recursions = [1, 2]
    objectives = ["current", "loss"]   # least current, least loss (default: the drive's controller.objective)
    u_dc_scale = [1.0, 0.85]
    T_magnet_degC = [20.0, 120.0]
    T_winding_degC = [20.0]
    thermal_models = [0, 1]             # the thermal network off, on (default: the drive's [thermal]);
                                        # on, the temperatures above are where it starts
    lut_grids = [[41, 41], [21, 21]]    # an extension: the 2-D tables' points (torque, speed or V_max/w)

A bad specification raises SpecError naming the file and the key.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

from scenarios.core.constants import T_REFERENCE_K, U_DC_SCALE_MAX, ZERO_CELSIUS_K
from scenarios.core.fmu_ranges import fmu_ranges
from scenarios.drives.description import OBJECTIVES, DriveDescription, controller_has_objective, load_drive
from scenarios.runs.simulate import METHODS, STUDY_CONDITIONS, Conditions, RunSpec
from scenarios.vehicle.cycles import STANDARD_CYCLES

#: degC, the default magnet and winding temperatures: the reference the maps and R_s hold at
T_DEFAULT_DEGC = T_REFERENCE_K - ZERO_CELSIUS_K

#: the recursions the controller accepts (its `recursion` parameter)
RECURSIONS = (0, 1, 2)


class SpecError(ValueError):
    """A bad study specification; the message names the file and the key."""


@dataclass(frozen=True)
class Run:
    """One run of a study: its columns in runs.parquet. `drive` is the drive description's path
    ("" = the default drive), `cycle` a standard cycle's name or a CSV's path; the window is
    (NaN, NaN) for the whole cycle."""

    drive: str = ""
    cycle: str = "WLTC3b"
    window_start_s: float = math.nan
    window_end_s: float = math.nan
    method: str = "ferrari"
    recursion: int = 2
    u_dc_scale: float = 1.0
    T_magnet_degC: float = T_DEFAULT_DEGC
    T_winding_degC: float = T_DEFAULT_DEGC
    lut_n_torque: int | None = None  # the 2-D tables' grid points; None: the controller's default
    lut_n_speed: int | None = None
    command_check: int = 1           # the controller's: 1 replaces failing commands, 0 studies a method alone
    thermal_model: int | None = None  # 1: the thermal network on, 0: off; None: the drive's [thermal]
    objective: str | None = None     # what the controller minimises: "current" or "loss"; None: the drive's

    @property
    def lut_grid(self) -> tuple[int, int] | None:
        return None if self.lut_n_torque is None else (self.lut_n_torque, self.lut_n_speed)

    @property
    def window(self) -> tuple[float, float] | None:
        return None if math.isnan(self.window_start_s) else (self.window_start_s, self.window_end_s)

    def conditions(self) -> Conditions:
        """The run's operating conditions; one of the compare study's (STUDY_CONDITIONS, or the
        default) with its name and its very values when the run's are those, else named by them."""
        T_m, T_w = self.T_magnet_degC + ZERO_CELSIUS_K, self.T_winding_degC + ZERO_CELSIUS_K
        thermal = None if self.thermal_model is None else bool(self.thermal_model)
        for c in (Conditions(), *STUDY_CONDITIONS):
            in_celsius = (c.T_magnet - ZERO_CELSIUS_K, c.T_winding - ZERO_CELSIUS_K)
            if c.u_dc_scale == self.u_dc_scale and c.thermal == thermal and (
                    (c.T_magnet, c.T_winding) == (T_m, T_w) or
                    in_celsius == (self.T_magnet_degC, self.T_winding_degC)):
                return replace(c)
        name = (f"u_dc x{self.u_dc_scale:g}, magnets {self.T_magnet_degC:g} degC, "
                f"windings {self.T_winding_degC:g} degC")
        if thermal is not None:
            name += f", thermal network {'on' if thermal else 'off'}"
        return Conditions(name, u_dc_scale=self.u_dc_scale, T_magnet=T_m, T_winding=T_w, thermal=thermal)

    @classmethod
    def of_conditions(cls, c: Conditions, **columns) -> Run:
        """The run at conditions `c` (inverse of conditions())."""
        return cls(u_dc_scale=c.u_dc_scale, T_magnet_degC=c.T_magnet - ZERO_CELSIUS_K,
                   T_winding_degC=c.T_winding - ZERO_CELSIUS_K,
                   thermal_model=None if c.thermal is None else int(c.thermal), **columns)

    @classmethod
    def of_row(cls, row: dict) -> Run:
        return cls(**{f.name: row[f.name] for f in fields(cls)})

    def to_dict(self) -> dict:
        return asdict(self)


#: [study] key (a list) -> Run field; the [[run]] tables use the field names
AXES = {"drives": "drive", "cycles": "cycle", "methods": "method", "recursions": "recursion",
        "u_dc_scale": "u_dc_scale", "T_magnet_degC": "T_magnet_degC", "T_winding_degC": "T_winding_degC",
        "lut_grids": "lut_grid", "command_checks": "command_check", "thermal_models": "thermal_model",
        "objectives": "objective"}
RUN_KEYS = tuple(AXES.values()) + ("window_s",)

#: the controller's bounds of lut_n_torque and lut_n_speed (its modelDescription)
LUT_POINTS_MIN, LUT_POINTS_MAX = 3, 1001
RUN_COLUMNS = tuple(f.name for f in fields(Run))
#: the most runs one study may hold: at a run a second on every core of a large machine this is
#: already a day; the plan is counted against it before any run is built
MAX_RUNS = 100_000


@dataclass(frozen=True)
class StudySpec:
    """The runs of a study, in the specification's order (product: the axes above, the last
    varying fastest), and the file they came from."""

    path: Path | None
    runs: tuple[Run, ...]


def _where(path: Path | None, key: str) -> str:
    return f"{path or '<study>'}: {key}"


def _number(v, path, key, integer=False):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not isinstance(v, int)):
        raise SpecError(f"{_where(path, key)}: expected {'an integer' if integer else 'a number'}, got {v!r}")
    try:
        ok = math.isfinite(v)
    except OverflowError:  # an integer beyond a float's range
        ok = False
    if not ok:
        raise SpecError(f"{_where(path, key)}: expected a finite number, got {v!r}")
    return int(v) if integer else float(v)


def _value(field: str, v, path: Path | None, key: str):
    """One axis value, checked and converted to the Run field's type."""
    if field == "drive":
        if not isinstance(v, str) or not v:
            raise SpecError(f"{_where(path, key)}: expected the path of a drive description (TOML), got {v!r}")
        p = Path(v) if Path(v).is_absolute() or path is None else path.parent / v
        if not p.is_file():
            raise SpecError(f"{_where(path, key)}: drive description not found: {p}")
        return str(p.resolve())
    if field == "cycle":
        if not isinstance(v, str) or not v:
            raise SpecError(f"{_where(path, key)}: expected a cycle name or CSV path, got {v!r}")
        if v.lower() in (c.lower() for c in STANDARD_CYCLES):
            return next(c for c in STANDARD_CYCLES if c.lower() == v.lower())
        p = Path(v) if Path(v).is_absolute() or path is None else path.parent / v
        if not p.is_file():
            raise SpecError(f"{_where(path, key)}: {v!r} is neither a standard cycle "
                            f"({', '.join(STANDARD_CYCLES)}) nor a CSV file ({p} not found)")
        return str(p.resolve())
    if field == "method":
        if v not in METHODS:
            raise SpecError(f"{_where(path, key)}: expected one of {', '.join(METHODS)}, got {v!r}")
        return v
    if field == "objective":
        if v not in OBJECTIVES:
            raise SpecError(f"{_where(path, key)}: expected one of {', '.join(OBJECTIVES)}, got {v!r}")
        if v != "current" and not controller_has_objective():
            raise SpecError(f"{_where(path, key)}: {v!r} needs FMUs with the `objective` parameter: rebuild them")
        return v
    if field == "lut_grid":
        if not isinstance(v, list) or len(v) != 2:
            raise SpecError(f"{_where(path, key)}: expected a [torque points, speed points] pair, got {v!r}")
        n = tuple(_number(x, path, key, integer=True) for x in v)
        if not all(LUT_POINTS_MIN <= x <= LUT_POINTS_MAX for x in n):
            raise SpecError(f"{_where(path, key)}: grid points must be in [{LUT_POINTS_MIN}, {LUT_POINTS_MAX}], "
                            f"got {v}")
        return n
    if field == "recursion":
        r = _number(v, path, key, integer=True)
        if r not in RECURSIONS:
            raise SpecError(f"{_where(path, key)}: expected one of {RECURSIONS}, got {r}")
        return r
    if field in ("command_check", "thermal_model"):
        r = _number(v, path, key, integer=True)  # 0 or 1, as documented: a TOML true is not an integer
        if r not in (0, 1):
            raise SpecError(f"{_where(path, key)}: expected 0 or 1, got {r}")
        return r
    x = _number(v, path, key)
    if field == "u_dc_scale" and not 0.0 < x <= U_DC_SCALE_MAX:
        raise SpecError(f"{_where(path, key)}: expected 0 < u_dc_scale <= {U_DC_SCALE_MAX:g}, got {x}")
    if field.endswith("_degC"):
        r = fmu_ranges()["T_magnet_ref"]  # the FMUs' temperature range
        lo, hi = r.lo - ZERO_CELSIUS_K, r.hi - ZERO_CELSIUS_K
        if not lo <= x <= hi:
            raise SpecError(f"{_where(path, key)}: expected a temperature in [{lo:g}, {hi:g}] degC (the FMUs' "
                            f"range), got {x}")
    return x


def _window(v, path: Path | None, key: str) -> tuple[float, float]:
    if not isinstance(v, list) or len(v) != 2:
        raise SpecError(f"{_where(path, key)}: expected one [start, end] pair in s, got {v!r}")
    a, b = (_number(x, path, key) for x in v)
    if not 0.0 <= a < b:
        raise SpecError(f"{_where(path, key)}: expected 0 <= start < end, got [{a}, {b}]")
    return a, b


def _check_cycles(runs: list[Run], path: Path | None, cycle_key: str, window_key: str) -> None:
    """Each cycle readable and each window inside its cycle: a bad cycle is a bad spec, not a
    failed run (the client reads the cycles anyway: their samples enter the runs' keys)."""
    from scenarios.vehicle.cycles import load_cycle
    by_cycle: dict[str, list[Run]] = {}
    for r in runs:
        by_cycle.setdefault(r.cycle, []).append(r)
    for cycle, its_runs in by_cycle.items():
        try:
            c = load_cycle(cycle)
        except (OSError, ValueError) as e:
            raise SpecError(f"{_where(path, cycle_key)}: {e}") from None
        for r in its_runs:
            if r.window and not (c.time_s[0] <= r.window[0] and r.window[1] <= c.time_s[-1]):
                raise SpecError(f"{_where(path, window_key)}: window [{r.window[0]:g}, {r.window[1]:g}] s is not "
                                f"inside {cycle} [{c.time_s[0]:g}, {c.time_s[-1]:g}] s")


def _run(values: dict, window: tuple[float, float]) -> Run:
    values = dict(values)
    grid = values.pop("lut_grid", None)
    values.setdefault("window_start_s", window[0])
    values.setdefault("window_end_s", window[1])
    return Run(**values, **({} if grid is None else dict(lut_n_torque=grid[0], lut_n_speed=grid[1])))


def parse(data: dict, path: Path | None = None) -> StudySpec:
    """The runs of a parsed TOML document (`path`: where relative paths start, and error messages)."""
    unknown = set(data) - {"study", "run"}
    if unknown:
        raise SpecError(f"{_where(path, sorted(unknown)[0])}: unknown table (expected [study] and/or [[run]])")
    study = data.get("study", {})
    if not isinstance(study, dict):
        raise SpecError(f"{_where(path, 'study')}: expected a table")
    for k in study:
        if k not in AXES and k != "window_s":
            raise SpecError(f"{_where(path, 'study.' + k)}: unknown key (expected one of "
                            f"{', '.join([*AXES, 'window_s'])})")
    window = _window(study["window_s"], path, "study.window_s") if "window_s" in study else (math.nan, math.nan)
    explicit = data.get("run")
    runs: list[Run] = []
    if explicit is not None:
        if not isinstance(explicit, list) or not all(isinstance(r, dict) for r in explicit) or not explicit:
            raise SpecError(f"{_where(path, 'run')}: expected a non-empty list of [[run]] tables")
        axes_given = [k for k in study if k in AXES]
        if axes_given:
            raise SpecError(f"{_where(path, 'study.' + axes_given[0])}: the axes' product and an explicit [[run]] "
                            "list exclude each other (only study.window_s may go with [[run]])")
        if len(explicit) > MAX_RUNS:
            raise SpecError(f"{_where(path, 'run')}: at most {MAX_RUNS} runs in a study, got {len(explicit)}")
        for i, r in enumerate(explicit):
            values = {}
            for k, v in r.items():
                key = f"run[{i}].{k}"
                if k not in RUN_KEYS:
                    raise SpecError(f"{_where(path, key)}: unknown key (expected one of {', '.join(RUN_KEYS)})")
                if k == "window_s":
                    values["window_start_s"], values["window_end_s"] = _window(v, path, key)
                else:
                    values[k] = _value(k, v, path, key)
            runs.append(_run(values, window))
        _check_cycles(runs, path, "run[].cycle", "run[].window_s")
    else:
        lists = []
        count = 1
        for key, field in AXES.items():
            if key not in study:
                lists.append([getattr(Run(), field)])
                continue
            v = study[key]
            # a scalar is a list of one; a grid is a pair, so lut_grids is always a list of pairs
            v = v if isinstance(v, list) and (field != "lut_grid" or all(isinstance(x, list) for x in v)) else [v]
            if not v:
                raise SpecError(f"{_where(path, 'study.' + key)}: empty list")
            count *= len(v)
            if count > MAX_RUNS:  # counted before a run is built or a value checked
                raise SpecError(f"{_where(path, 'study.' + key)}: at most {MAX_RUNS} runs in a study, the axes' "
                                f"product has more")
            lists.append([_value(field, x, path, f"study.{key}") for x in v])
        for combo in itertools.product(*lists):
            runs.append(_run(dict(zip(AXES.values(), combo)), window))
        _check_cycles(runs, path, "study.cycles", "study.window_s")
    seen: set[Run] = set()
    for r in runs:  # linear: a set, not a count per run
        if r in seen:
            raise SpecError(f"{_where(path, 'run' if explicit else 'study')}: the same run twice: {r}")
        seen.add(r)
    return StudySpec(path, tuple(runs))


def load_spec(path: str | Path) -> StudySpec:
    """Read and check a study specification file (bounded: scenarios.core.boundary.load_toml)."""
    from scenarios.core.boundary import InputError, load_toml
    path = Path(path)
    try:
        data, _ = load_toml(path, "study specification (TOML)")
    except InputError as e:
        raise SpecError(str(e)) from None
    return parse(data, path)


def run_spec(run: Run, drive: DriveDescription | None = None) -> RunSpec:
    """The simulation's specification of a run (its drive loaded already, or loaded here)."""
    drive = drive if drive is not None else load_drive(run.drive or None)
    return RunSpec(drive=drive, method=run.method, recursion=run.recursion, conditions=run.conditions(),
                   lut_grid=run.lut_grid, command_check=run.command_check, objective=run.objective)
