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
4. Bounded: a repair that changes more than MAX_CHANGED_FRACTION of the grid's points, or an
   apparent inductance by more than MAX_INDUCTANCE_FACTOR, is refused (MapImportError: exit 2): a
   map that needs that much has a convention error (a flux's sign, swapped axes), not defects, and
   the refusal names the likely one.
5. Verified before it is written: the FMUs' verdict on the result (scenarios.maps.fmu_verdict)
   and a short simulation (short_simulation: IpmsmDrive for a few ms at a few operating points);
   written only if every FMU accepts it and the simulation runs, else nothing is written (exit 1).
   The metadata the repair relied on are written with it (`--I-max` as `# I_max_A`).
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

#: The largest share of a grid's points a repair may change: it mends defects (a fold at the
#: rim, measurement noise), a few per cent of a map; the default map with psi_q negated needs 98.6 %.
MAX_CHANGED_FRACTION = 0.10
#: The largest factor by which a repair may change a map's apparent inductance (L_d, L_q at the
#: drive's current): a repair keeps the machine; 0.57 mH -> 2.7e-10 H is another one.
MAX_INDUCTANCE_FACTOR = 2.0
#: The short simulation: IpmsmDrive for SIMULATION_STEPS sample times from standstill and at
#: SIMULATION_SPEED_SHARE of the top speed, at SIMULATION_TORQUE_SHARE of +-T_max.
SIMULATION_STEPS = 30
SIMULATION_SPEED_SHARE = 0.3
SIMULATION_TORQUE_SHARE = 0.5


@dataclass
class Repair:
    changes: list = field(default_factory=list)   # what was done, in words
    fmus: list = field(default_factory=list)      # FmuVerdict
    out: Path | None = None                       # None: not written
    simulation: list = field(default_factory=list)  # the short simulation's failures, in words

    @property
    def accepted(self) -> bool:
        return all(v.accepted for v in self.fmus) and not self.simulation


def apparent_inductances(fmap: FluxMap, I: float) -> tuple[float, float]:
    """(L_d, L_q), H: the secants psi_d(-I, 0) - psi_d(0, 0) over -I and psi_q(0, I) - psi_q(0, 0)
    over I on the grid's nearest points (I within the grid)."""
    j0, k0 = int(np.argmin(np.abs(fmap.i_d))), int(np.argmin(np.abs(fmap.i_q)))
    jd = int(np.argmin(np.abs(fmap.i_d + I)))
    kq = int(np.argmin(np.abs(fmap.i_q - I)))
    di_d, di_q = fmap.i_d[jd] - fmap.i_d[j0], fmap.i_q[kq] - fmap.i_q[k0]
    L_d = (fmap.psi_d[jd, k0] - fmap.psi_d[j0, k0]) / di_d if di_d else float("nan")
    L_q = (fmap.psi_q[j0, kq] - fmap.psi_q[j0, k0]) / di_q if di_q else float("nan")
    return float(L_d), float(L_q)


def likely_cause(fmap: FluxMap, I: float) -> str:
    """What convention error a map that needs a large repair most likely has, in words."""
    L_d, L_q = apparent_inductances(fmap, I)
    causes = []
    if L_q < 0:
        causes.append("psi_q has the wrong sign? (it falls as i_q rises; the contract's psi_q rises with i_q, "
                      "psi_q = L_q i_q)")
    if L_d < 0:
        causes.append("psi_d has the wrong sign? (it falls as i_d rises; the contract's psi_d = psi_m + L_d i_d "
                      "rises with i_d)")
    if not causes:
        causes.append("the axes or units differ from the contract's? (i_d, i_q peak A; psi_d, psi_q Wb; the magnet "
                      "on +d: docs/maps.md)")
    return "; ".join(causes)


def check_bounds(path: Path, before: FluxMap, after: FluxMap, changed: int, I: float) -> None:
    """Refuses (MapImportError) a repair beyond MAX_CHANGED_FRACTION or MAX_INDUCTANCE_FACTOR."""
    n = after.psi_d.size
    if changed > MAX_CHANGED_FRACTION * n:
        raise MapImportError(path, "psi_d, psi_q", f"a map a repair changes in at most "
                             f"{MAX_CHANGED_FRACTION:.0%} of its points",
                             f"{changed} of {n} points to change: not repaired; {likely_cause(before, I)}")
    for name, a, b in zip(("L_d", "L_q"), apparent_inductances(before, I), apparent_inductances(after, I)):
        ratio = b / a if a else float("inf")
        if not (1.0 / MAX_INDUCTANCE_FACTOR <= ratio <= MAX_INDUCTANCE_FACTOR):
            raise MapImportError(path, "psi_d, psi_q", f"a repair that changes the apparent {name} by at most a "
                                 f"factor {MAX_INDUCTANCE_FACTOR:g}",
                                 f"{name} {a:.3g} H -> {b:.3g} H: not repaired; {likely_cause(before, I)}")


def short_simulation(csv: Path, params: dict, build: Path) -> list[str]:
    """IpmsmDrive on the map for SIMULATION_STEPS sample times at each operating point (standstill
    and SIMULATION_SPEED_SHARE of the top speed; +-SIMULATION_TORQUE_SHARE of T_max): what failed,
    in words (empty: it ran, every output finite, the torque of the command's sign)."""
    from fmpy import read_model_description

    from scenarios.cosim.drive_fmu import DriveFmu
    from scenarios.cosim.fmu import CosimError

    path = build / "fmu" / "IpmsmDrive.fmu"
    names = {v.name for v in read_model_description(str(path)).modelVariables}
    given = {k: v for k, v in params.items() if k in names and k != "flux_map"}
    w_top = float(params.get("w_m_max", 0.0) or 0.0)
    failures = []
    for w_m in (0.0, SIMULATION_SPEED_SHARE * w_top):
        for sign in (1.0, -1.0):
            where = f"w_m = {w_m:.4g} rad/s, T_ref = {sign * SIMULATION_TORQUE_SHARE:+g} T_max"
            try:
                d = DriveFmu(path, {**given, "flux_map": str(csv)}, w_m=w_m, instance_name="repair-check")
            except Exception as e:  # noqa: BLE001 - the FMU's refusal, reported in words
                failures.append(f"{where}: initialisation failed: {e}")
                continue
            try:
                T_ref = sign * SIMULATION_TORQUE_SHARE * abs(d.get("T_max"))
                for _ in range(SIMULATION_STEPS):
                    s = d.advance(d.sample_time, T_ref, w_m, d.get("u_dc"), 293.15, 293.15)
                if not np.isfinite(s.T_e) or s.T_e * T_ref <= 0:
                    failures.append(f"{where}: after {SIMULATION_STEPS} sample times T_e = {s.T_e:.4g} N.m for "
                                    f"T_ref = {T_ref:.4g} N.m")
            except CosimError as e:
                failures.append(f"{where}: {e}")
            finally:
                d.close()
    return failures


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
    source_map = fmap
    no_magnet, box, found, _, rect = analyse(fmap, I_lim)
    n = found.count()
    changed_points = 0
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
        changed_points = int(changed.sum())
        moved = max(np.abs(psi_d - fmap.psi_d).max(), np.abs(psi_q - fmap.psi_q).max())
        changes.append(f"no legal sub-grid holds the drive's currents (I_max {I_lim:g} A): monotone projection, "
                       f"{int(changed.sum())} points changed by up to {moved:.3g} Wb (each flux made strictly "
                       "increasing along its axis from zero current outward)")
        fmap = FluxMap(fmap.i_d, fmap.i_q, psi_d, psi_q, fmap.metadata)
        if legal.defects(fmap).folds.size:
            changes.append("the projected map still folds somewhere (its incremental inductances): see the FMUs' "
                           "verdict")
    check_bounds(path, source_map, fmap, changed_points, I_lim)
    if I_max is not None:  # what the repair relied on is the map's: map check, run and map show read it
        fmap = FluxMap(fmap.i_d, fmap.i_q, fmap.psi_d, fmap.psi_q, {**fmap.metadata, "I_max_A": f"{I_lim:g}"})
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
    # verified where the FMUs read it (a temporary folder), then written in place only if it passes
    with tempfile.TemporaryDirectory(prefix="ipmsm-repair-") as work:
        tmp = Path(work) / out.name
        write_flux_map(tmp, fmap, comment)
        fmus = verdicts(tmp, params, build)
        simulation = short_simulation(tmp, params, build) if all(v.accepted for v in fmus) else []
    result = Repair(changes, fmus, None, simulation)
    if result.accepted:
        write_atomically(out, lambda t: write_flux_map(t, fmap, comment))
        result.out = out
    return result


def _is_metadata(line: str) -> bool:
    """A '# key: value' line (one-word key), as the readers take it (scenarios.maps.flux_map)."""
    key, sep, _ = line.strip()[1:].partition(":")
    return bool(sep and key.strip() and " " not in key.strip())


__all__ = ["Repair", "fill_holes", "read_with_holes", "repair_map"]
