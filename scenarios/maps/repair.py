"""python -m scenarios map repair FILE --out X.csv: a map the FMUs accept, every change stated.

Steps, each stated in the CSV's comments and on stdout:
1. Holes (NaN, e.g. a measurement inside a current circle only): filled by extending each flux
   linearly along its own axis from the last two given points of the line (psi_d along i_d,
   psi_q along i_q: the incremental self-inductance at the rim is kept, so the extension rises as
   the data do); points still without a value (rows or columns with no data at all) then along the
   other axis the same way. The made points are counted and bounded.
2. Half and quarter maps: completed by the machine's symmetry (scenarios.maps.symmetry, through
   the importer), and format conversions (scenarios.maps.importer).
3. Defects (scenarios.maps.legal): if the largest legal sub-grid holds the drive's currents
   (the half disc i_d <= 0 within I_max for a PM machine, the whole disc without magnet), the
   map is cropped to it (no value changed); otherwise a monotone projection (each flux made
   strictly increasing along its axis from zero current outward; points changed are counted).
4. The FMUs' verdict on the result (scenarios.maps.fmu_verdict): reported; exit 1 if one
   still refuses it.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenarios.core.boundary import printable
from scenarios.maps import legal
from scenarios.maps.check import analyse, machine_of
from scenarios.maps.error import MapImportError
from scenarios.maps.flux_map import FluxMap, read_flux_map, write_flux_map
from scenarios.maps.fmu_verdict import verdicts
from scenarios.maps.importer import import_map


@dataclass
class Repair:
    changes: list = field(default_factory=list)   # what was done, in words
    fmus: list = field(default_factory=list)      # FmuVerdict
    out: Path | None = None

    @property
    def accepted(self) -> bool:
        return all(v.accepted for v in self.fmus)


def fill_holes(i_d, i_q, psi_d, psi_q) -> tuple[np.ndarray, np.ndarray, int, str | None]:
    """NaN points filled by linear extension along the grid lines (module docstring, step 1)."""
    holes = np.isnan(psi_d) | np.isnan(psi_q)
    if not holes.any():
        return psi_d, psi_q, 0, None
    psi_d, psi_q = psi_d.copy(), psi_q.copy()
    psi_d[holes] = np.nan
    psi_q[holes] = np.nan
    for first in (True, False):
        # first pass: each flux along its own axis; second: along the other axis
        for psi, axis in ((psi_d, 0 if first else 1), (psi_q, 1 if first else 0)):
            _extend_lines(psi, i_d if axis == 0 else i_q, axis)
    if np.isnan(psi_d).any() or np.isnan(psi_q).any():
        raise MapImportError(None, "psi_d, psi_q", "at least two given points on some grid line of each flux",
                             "too few points to extend from")
    I = np.hypot(*np.meshgrid(i_d, i_q, indexing="ij"))
    given_r = float(I[~holes].max())
    note = (f"{int(holes.sum())} points without a value (NaN; the given points reach |i| = {given_r:.4g} A) made by "
            f"linear extension along the grid lines from the last two given points (|i| of the made points "
            f"{I[holes].min():.4g} ... {I[holes].max():.4g} A)")
    return psi_d, psi_q, int(holes.sum()), note


def _extend_lines(psi: np.ndarray, axis_values: np.ndarray, axis: int) -> None:
    p = np.moveaxis(psi, axis, 1)   # lines along axis 1, written through
    for line in p:
        ok = np.nonzero(~np.isnan(line))[0]
        if len(ok) < 2:
            continue
        lo, hi = ok[0], ok[-1]
        if not np.isnan(line[lo:hi + 1]).any():
            x = axis_values
            s_hi = (line[hi] - line[hi - 1]) / (x[hi] - x[hi - 1])
            s_lo = (line[lo + 1] - line[lo]) / (x[lo + 1] - x[lo])
            line[hi + 1:] = line[hi] + s_hi * (x[hi + 1:] - x[hi])
            line[:lo] = line[lo] + s_lo * (x[:lo] - x[lo])


def read_with_holes(path: Path) -> tuple[Path, list]:
    """A contract CSV whose flux values may be NaN (read within the FMUs' limits, errors naming
    the line): the holes filled (fill_holes) into a temporary CSV for the importer; other files,
    and CSVs without a hole, as they are. Returns (path to import, notes)."""
    if path.suffix.lower() != ".csv":
        return path, []
    fmap = read_flux_map(path, holes=True)
    if not (np.isnan(fmap.psi_d).any() or np.isnan(fmap.psi_q).any()):
        return path, []
    psi_d, psi_q, _, note = fill_holes(fmap.i_d, fmap.i_q, fmap.psi_d.copy(), fmap.psi_q.copy())
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".csv")
    os.close(fd)
    write_flux_map(tmp, FluxMap(fmap.i_d, fmap.i_q, psi_d, psi_q, fmap.metadata), f"{path.name}, holes filled")
    return Path(tmp), [note]


def repair_map(path: Path, out: Path, build: Path, I_max: float | None = None, drive=None) -> Repair:
    path = Path(path)
    try:  # the readers' refusals (a header, a metadata value, a grid too small): bad input, exit 2
        source, changes = read_with_holes(path)
        try:
            imported = import_map(source)
        finally:
            if source != path:
                source.unlink(missing_ok=True)
        changes += imported.notes
        fmap = imported.flux_map()
    except MapImportError:
        raise
    except Exception as e:  # noqa: BLE001 - scipy's and the parsers' own words, named with the file
        raise MapImportError(path, "(file)", "a readable flux map", printable(str(e))) from None
    params, assumed, _ = machine_of(path, fmap, I_max, drive)
    I_lim = float(params["I_max"])
    no_magnet, box, found, _, rect = analyse(fmap, I_lim)
    n = found.count()
    if n == 0:
        changes.append("no defect in the grid's values or on its spline: no value changed")
    elif rect is not None:
        full = fmap
        while rect is not None:  # the cropped map's spline differs at its new edges: until it has no defect
            a, b, c, d = rect
            fmap = FluxMap(fmap.i_d[a:b + 1], fmap.i_q[c:d + 1], fmap.psi_d[a:b + 1, c:d + 1],
                           fmap.psi_q[a:b + 1, c:d + 1], fmap.metadata)
            left = legal.defects(fmap).all()
            rect = legal.legal_rectangle(fmap, left, box) if len(left) else None
            if len(left) and rect is None:
                break
        dropped = len(full.i_d) * len(full.i_q) - len(fmap.i_d) * len(fmap.i_q)
        changes.append(f"cropped to the largest legal sub-grid holding the drive's currents (I_max {I_lim:g} A"
                       f"{', magnet-free: the whole disc' if no_magnet else ', PM: the half disc i_d <= 0'}): i_d "
                       f"{fmap.i_d[0]:g} ... {fmap.i_d[-1]:g} A, i_q {fmap.i_q[0]:g} ... {fmap.i_q[-1]:g} A (was "
                       f"{full.i_d[0]:g} ... {full.i_d[-1]:g} A, {full.i_q[0]:g} ... {full.i_q[-1]:g} A); {dropped} "
                       f"points dropped, no value changed; "
                       + (f"{len(left)} defects remain inside it (no smaller legal sub-grid holds the drive's "
                          "currents; the FMUs' verdict below decides)" if len(left)
                          else f"{n} defects were outside it"))
    else:
        j0, k0 = int(np.argmin(np.abs(fmap.i_d))), int(np.argmin(np.abs(fmap.i_q)))
        psi_d, psi_q, changed = legal.monotone_projection(fmap, j0, k0)
        moved = max(np.abs(psi_d - fmap.psi_d).max(), np.abs(psi_q - fmap.psi_q).max())
        changes.append(f"no legal sub-grid holds the drive's currents (I_max {I_lim:g} A): monotone projection, "
                       f"{int(changed.sum())} points changed by up to {moved:.3g} Wb (each flux made strictly "
                       "increasing along its axis from zero current outward)")
        fmap = FluxMap(fmap.i_d, fmap.i_q, psi_d, psi_q, fmap.metadata)
        if legal.defects(fmap).folds.size:
            changes.append("the projected map still folds somewhere (its incremental inductances): see the FMUs' "
                           "verdict")
    original = []
    if path.suffix.lower() == ".csv":  # the source's own words (provenance), metadata lines aside
        original = [f"Original: {line.strip()[1:].strip()}" for line in path.read_text().splitlines()
                    if line.strip().startswith("#") and not _is_metadata(line)]
    comment = "\n".join(original + [f"Repaired by scenarios.maps.repair from {path} ({imported.source_format})."] +
                        [f"Repair change: {c}" for c in changes] +
                        [f"Repair assumption: {a}" for a in assumed] +
                        [f"Import warning: {w}" for w in imported.warnings])
    out.parent.mkdir(parents=True, exist_ok=True)
    from scenarios.core.boundary import write_atomically  # 0644, a regular file only (docs/inputs.md)
    write_atomically(out, lambda tmp: write_flux_map(tmp, fmap, comment))
    return Repair(changes, verdicts(out, params, build), out)


def _is_metadata(line: str) -> bool:
    """A '# key: value' line (one-word key), as the readers take it (scenarios.maps.flux_map)."""
    key, sep, _ = line.strip()[1:].partition(":")
    return bool(sep and key.strip() and " " not in key.strip())


__all__ = ["Repair", "fill_holes", "read_with_holes", "repair_map"]
