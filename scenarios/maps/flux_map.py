"""Flux maps in the contract's CSV format (docs/spec/INTERFACE.md), read and interpolated
with scipy: an implementation independent of the FMUs' C++ one, used by the scenarios and as
the reference in the tests."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.interpolate import RectBivariateSpline

from scenarios.core.paths import located
from scenarios.maps.metadata import MetadataError, check_metadata, metadata_value

#: the degree of the map's interpolating splines (bicubic)
SPLINE_DEGREE = 3


@dataclass
class FluxMap:
    """psi_d(i_d, i_q), psi_q(i_d, i_q) on a rectangular grid (A, Wb, peak values)."""

    i_d: np.ndarray  # ascending axis, A
    i_q: np.ndarray  # ascending axis, A
    psi_d: np.ndarray  # shape (len(i_d), len(i_q)), Wb
    psi_q: np.ndarray
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        # Interpolating (s=0) bicubic splines: a cubic needs more points than its degree per axis
        n = (len(self.i_d), len(self.i_q))
        if min(n) <= SPLINE_DEGREE:
            raise ValueError(f"a grid of at least {SPLINE_DEGREE + 1} currents on each axis (the map's bicubic "
                             f"spline), got {n[0]} x {n[1]}")
        if not (np.any(self.psi_d) or np.any(self.psi_q)):
            raise ValueError("flux values: all of them are zero (no machine has no flux linkage anywhere)")
        self._sd = RectBivariateSpline(self.i_d, self.i_q, self.psi_d, kx=3, ky=3, s=0)
        self._sq = RectBivariateSpline(self.i_d, self.i_q, self.psi_q, kx=3, ky=3, s=0)

    @property
    def psi_m(self) -> float:
        """PM flux linkage psi_d(0, 0), Wb."""
        return float(self._sd.ev(0.0, 0.0))

    def flux(self, i_d, i_q, psi_d_shift: float = 0.0, dx: int = 0, dy: int = 0):
        """(psi_d, psi_q) at currents (arrays broadcast); psi_d_shift models magnet temperature.
        dx, dy > 0: their partial derivatives of those orders in i_d, i_q instead (H, H/A, ...)."""
        i_d, i_q = np.broadcast_arrays(np.asarray(i_d, float), np.asarray(i_q, float))
        shift = psi_d_shift if dx == dy == 0 else 0.0
        return self._sd.ev(i_d, i_q, dx=dx, dy=dy) + shift, self._sq.ev(i_d, i_q, dx=dx, dy=dy)

    def flux_on_grid(self, i_d, i_q, dx: int = 0, dy: int = 0):
        """flux() on the grid i_d x i_q (1-D ascending axes; arrays indexed [i_d, i_q]): the splines'
        tensor-product evaluation, far faster than flux() at the same points scattered."""
        return (self._sd(i_d, i_q, dx=dx, dy=dy, grid=True), self._sq(i_d, i_q, dx=dx, dy=dy, grid=True))

    def number(self, key: str, default: float | None = None) -> float | int:
        """The value of a '# key: value' line of a contract key (scenarios.maps.metadata: the
        FMUs' rule; MetadataError for one it refuses); `default` where the map has none."""
        if key in self.metadata:
            return metadata_value(key, self.metadata[key])
        if default is None:
            raise KeyError(f"flux map has no metadata '{key}'")
        return default

#: the UTF-8 byte-order mark a spreadsheet export may begin with (the FMUs' reader skips it too)
BOM = "\ufeff"

#: the default motor's flux map (tools/default_motor/ makes it); its metadata is the motor's data sheet
DEFAULT_MAP = located("fmu_src/resources/ev_ipmsm_default.csv")


@dataclass(frozen=True)
class MotorData:
    """What the scenarios need of a motor besides its flux linkages, from a map's `# key: value`
    metadata (the same numbers the FMUs' parameters default to)."""

    pole_pairs: int
    R_s: float            # Ohm at T_winding_ref
    T_winding_ref: float  # K
    alpha_cu: float       # 1/K
    I_max: float          # A, peak
    k_u: float            # V_max = k_u u_dc / sqrt 3

    @classmethod
    def of(cls, fmap: FluxMap) -> MotorData:
        return cls(int(fmap.number("pole_pairs")), fmap.number("R_s_ohm"), fmap.number("T_winding_ref_K"),
                   fmap.number("alpha_cu_per_K"), fmap.number("I_max_A"), fmap.number("k_u"))


def read_flux_map(path: str | Path, holes: bool = False) -> FluxMap:
    """Read the contract's CSV: '#' lines (with '# key: value' metadata), header i_d,i_q,psi_d,psi_q.
    Within the FMUs' limits (scenarios.core.fmu_ranges.map_limits: a regular file of bounded
    bytes, lines and grid), refused before more than the limit is read; errors name file and line.
    holes: a flux value may be NaN (a point without a measurement, for `map repair` to fill)."""
    from scenarios.core.boundary import InputError, decode_utf8, read_bounded
    from scenarios.core.fmu_ranges import map_limits
    path = Path(path)
    lim = map_limits()
    text = decode_utf8(path, read_bounded(path, lim.max_bytes, "flux map (CSV)"), "flux map (CSV)")
    text = text.removeprefix(BOM)  # as the FMUs' reader: spreadsheets export UTF-8 with one
    metadata = {}
    rows: list[str] = []
    linenos: list[int] = []
    header_seen = False
    for lineno, line in enumerate(text.splitlines(), 1):
        if len(line) > lim.max_line_chars:
            raise InputError(path, f"line {lineno}", f"at most {lim.max_line_chars} characters, the FMUs' limit")
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            key, sep, value = s[1:].partition(":")
            if sep and key.strip() and " " not in key.strip():
                metadata[key.strip()] = value.strip()
            continue
        if not header_seen:
            if [c.strip() for c in s.split(",")] != ["i_d", "i_q", "psi_d", "psi_q"]:
                raise ValueError(f"{path}: expected header i_d,i_q,psi_d,psi_q, got {s[:80]!r}")
            header_seen = True
            continue
        if len(rows) >= lim.max_points:
            raise InputError(path, f"line {lineno}", f"at most {lim.max_points} grid points, the FMUs' limit")
        rows.append(s)
        linenos.append(lineno)
    if not rows:
        raise InputError(path, "(file)", "a header i_d,i_q,psi_d,psi_q and grid rows")
    try:
        check_metadata(metadata)
    except MetadataError as e:  # as the FMUs' reader: the map is refused, naming the key
        raise InputError(path, e.key, f"{e.expected}, got {e.text[:80]!r} (docs/maps.md, \"Metadata\")") from None
    try:
        data = _parse_rows(rows)
        ok = data.ndim == 2 and data.shape[1] == 4 and all(map(_legal(holes), data.T[2:].ravel())) \
            and bool(np.isfinite(data[:, :2]).all())
    except ValueError:
        ok = False
    if not ok:  # the first bad row, by its line
        expected = "four numbers i_d,i_q,psi_d,psi_q, finite (a flux may be NaN)" if holes else \
            "four finite numbers i_d,i_q,psi_d,psi_q"
        for lineno, row in zip(linenos, rows):
            try:
                x = [float(v) for v in row.split(",")]
            except ValueError:
                x = []
            if len(x) != 4 or not all(map(math.isfinite, x[:2])) or not all(map(_legal(holes), x[2:])):
                raise InputError(path, f"line {lineno}", f"{expected}, got {row[:80]!r}")
    i_d = np.unique(data[:, 0])
    i_q = np.unique(data[:, 1])
    if max(len(i_d), len(i_q)) > lim.max_axis:
        raise InputError(path, "(grid)", f"at most {lim.max_axis} points per axis, the FMUs' limit; "
                         f"got {len(i_d)} x {len(i_q)}")
    if len(i_d) * len(i_q) != len(data):
        raise ValueError(f"{path}: not a full rectangular grid")
    psi_d = np.full((len(i_d), len(i_q)), np.nan)
    psi_q = np.full_like(psi_d, np.nan)
    j = np.searchsorted(i_d, data[:, 0])
    k = np.searchsorted(i_q, data[:, 1])
    psi_d[j, k] = data[:, 2]
    psi_q[j, k] = data[:, 3]
    given = np.zeros(psi_d.shape, dtype=bool)
    given[j, k] = True
    if not given.all():
        raise ValueError(f"{path}: duplicate or missing grid points")
    return FluxMap(i_d, i_q, psi_d, psi_q, metadata)


def _legal(holes: bool):
    """What a flux value may be: finite, or with holes allowed also NaN (never infinite)."""
    return (lambda x: math.isfinite(x) or math.isnan(x)) if holes else math.isfinite


def _parse_rows(rows: list[str]) -> np.ndarray:
    """The data rows as an (n, 4) array: numpy's C parser (a 511 x 511 map in 0.2 s, not 2 s), and
    where it refuses a row, the rows one by one, so that float() names the bad value."""
    try:
        data = np.loadtxt(rows, delimiter=",", ndmin=2, dtype=float)
        if data.shape[1] == 4:
            return data
    except ValueError:
        pass
    return np.array([[float(x) for x in s.split(",")] for s in rows])


def write_flux_map(path: str | Path, fmap: FluxMap, comment: str = "") -> None:
    """Write a map in the contract's CSV format."""
    lines = [f"# {c}" for c in comment.splitlines()] + [f"# {k}: {v}" for k, v in fmap.metadata.items()]
    lines.append("i_d,i_q,psi_d,psi_q")
    for a, x in enumerate(fmap.i_d):
        for b, y in enumerate(fmap.i_q):
            lines.append(f"{x:.12g},{y:.12g},{fmap.psi_d[a, b]:.15g},{fmap.psi_q[a, b]:.15g}")
    Path(path).write_text("\n".join(lines) + "\n")


def linear_flux_map(L_d: float, L_q: float, psi_m: float, i_range: float, n: int = 21, **metadata) -> FluxMap:
    """The map of a constant-inductance machine psi_d = L_d i_d + psi_m, psi_q = L_q i_q."""
    ax = np.linspace(-i_range, i_range, n)
    I_d, I_q = np.meshgrid(ax, ax, indexing="ij")
    return FluxMap(ax, ax.copy(), L_d * I_d + psi_m, L_q * I_q, dict(metadata))
