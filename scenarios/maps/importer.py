"""Flux maps from FEM tools into the contract's CSV (docs/spec/INTERFACE.md):

    import_map(path) -> ImportedMap     # read and convert, stating each conversion in .notes
    contract_csv(path) -> Path          # a CSV the FMUs read: the file itself, or its cached import
    write_contract_csv(imported, out)   # write it (temp file + rename: nothing half-written)

Formats (formats.py has their field names and sources): the contract CSV, SyR-e's
`fdfq_idiq_n*.mat` and motor-model `.mat` (with its machine data and iron-loss map, fitted
by iron_loss.py), Motor-CAD's Lab saturation-map `.mat` export, PLECS' look-up table.
Conversions (grid.py): RMS to peak, dq frame turned to put the PM on +d, meshgrid or
ndgrid layout, phase-advance grids resampled; half and quarter maps completed by the
machine's symmetry (symmetry.py). Bad files raise
MapImportError naming the file, the field and what was expected.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenarios.maps import formats as map_formats
from scenarios.maps import grid as map_grid
from scenarios.maps import iron_loss, symmetry
from scenarios.maps.error import MapImportError
from scenarios.maps.flux_map import FluxMap, read_flux_map, write_flux_map

__all__ = ["ImportedMap", "MapImportError", "contract_csv", "import_map", "write_contract_csv", "cache_dir"]

#: bump when a conversion changes, so that cached imports are made again
IMPORTER_VERSION = 3


@dataclass
class ImportedMap:
    """A flux map in the contract's terms: ascending axes i_d, i_q (A peak), psi_d, psi_q of shape
    (len(i_d), len(i_q)) (Wb peak), amplitude-invariant dq, PM flux on +d."""

    i_d: np.ndarray
    i_q: np.ndarray
    psi_d: np.ndarray
    psi_q: np.ndarray
    source_format: str                          # "contract CSV", "SyR-e", "Motor-CAD"
    notes: list = field(default_factory=list)   # what was converted, in words
    metadata: dict = field(default_factory=dict)  # '# key: value' lines (pole_pairs, R_s_ohm, ...)
    source: Path | None = None
    warnings: list = field(default_factory=list)  # what the map lacks, in words (nothing was changed)

    def flux_map(self) -> FluxMap:
        # metadata as the CSV holds it: text (FluxMap.number reads the leading number)
        return FluxMap(self.i_d, self.i_q, self.psi_d, self.psi_q, {k: str(v) for k, v in self.metadata.items()})


def import_map(path: str | Path) -> ImportedMap:
    """Read a flux map from a contract CSV or a FEM tool's .mat and convert it to the contract."""
    path = Path(path)
    try:
        return _import(path)
    except MapImportError as e:
        if e.file is None:
            e.file = path
        raise


def _import(path: Path) -> ImportedMap:
    if not path.is_file():
        raise MapImportError(path, "file", "an existing file", "no such file")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return _import_csv(path)
    if suffix != ".mat":
        raise MapImportError(path, "file", "a flux map: a contract .csv or a SyR-e / Motor-CAD .mat",
                             f"a '{path.suffix}' file")
    mat = map_formats.load_mat(path)
    layouts = [name for name, holds in (("PLECS", map_formats.is_plecs), ("Motor-CAD", map_formats.is_motorcad),
                                        ("SyR-e", map_formats.is_syre)) if holds(mat)]
    if len(layouts) > 1:  # which one is the map is not the importer's guess to make
        raise MapImportError(path, "variables", "one tool's layout (PLECS', Motor-CAD's or SyR-e's): save the map "
                             "without the other's variables", f"the layouts of {' and '.join(layouts)}")
    if map_formats.is_plecs(mat):
        raw = map_formats.read_plecs(path, mat)
    elif map_formats.is_motorcad(mat):
        raw = map_formats.read_motorcad(path, mat)
    elif map_formats.is_syre(mat):
        raw = map_formats.read_syre(path, mat)
    else:
        names = ", ".join(sorted(k for k in mat if not k.startswith("__"))[:12]) or "none"
        raise MapImportError(path, "variables", "SyR-e's Id, Iq, Fd, Fq (or motorModel.FluxMap_dq), Motor-CAD's "
                             "Id_Peak, Iq_Peak, Flux_Linkage_D, Flux_Linkage_Q or PLECS' imd, imq, Psid, Psiq", names)
    return _to_contract(raw, path)


def _import_csv(path: Path) -> ImportedMap:
    from scenarios.core.boundary import InputError
    _check_csv_numbers(path)
    try:
        fmap = read_flux_map(path)
    except InputError as e:  # read_flux_map names the line or the metadata key
        raise MapImportError(path, e.key, e.expected) from None
    except (ValueError, IndexError) as e:  # read_flux_map's message names the line's problem
        raise MapImportError(path, "rows", "the contract's CSV: header i_d,i_q,psi_d,psi_q, then numbers "
                             "forming a full rectangular grid", str(e).replace(f"{path}: ", "")) from e
    I_d, I_q = np.meshgrid(fmap.i_d, fmap.i_q, indexing="ij")
    raw = map_formats.RawMap("contract CSV", I_d, I_q, fmap.psi_d, fmap.psi_q,
                             ("i_d", "i_q", "psi_d", "psi_q"), square_axis0="i_d", metadata=dict(fmap.metadata))
    return _to_contract(raw, path)


CSV_COLUMNS = ("i_d", "i_q", "psi_d", "psi_q")


def _check_csv_numbers(path: Path) -> None:
    """NaN or Inf in a contract CSV, named by column and line (read_flux_map would only see a hole)."""
    from scenarios.core.boundary import InputError, read_bounded
    from scenarios.core.fmu_ranges import map_limits
    try:
        lines = read_bounded(path, map_limits().max_bytes, "flux map (CSV)").decode("utf-8").splitlines()
    except (InputError, UnicodeDecodeError) as e:
        raise MapImportError(path, "file", "a text file (the contract CSV)", f"unreadable ({e})") from e
    data = [(n, s) for n, s in enumerate(lines, 1) if s.strip() and not s.strip().startswith("#")][1:]
    try:  # the common case at numpy's speed: every value a finite number
        if np.isfinite(np.loadtxt([s for _, s in data], delimiter=",", ndmin=2, dtype=float)).all():
            return
    except ValueError:
        pass  # a malformed row: read_flux_map names it
    for n, s in data:
        for col, x in zip(CSV_COLUMNS, s.split(",")):
            try:
                v = float(x)
            except ValueError:
                continue  # read_flux_map names the malformed row
            if not np.isfinite(v):
                raise MapImportError(path, col, "finite numbers", f"{x.strip()} on line {n}")


def _to_contract(raw: map_formats.RawMap, path: Path) -> ImportedMap:
    notes = list(raw.notes)
    i_d, i_q, psi_d, psi_q, more = map_grid.as_2d(raw)
    notes += more
    warnings = list(raw.warnings)
    metadata = dict(raw.metadata)
    if raw.iron_loss is not None:
        _fit_iron_loss(raw, i_d, i_q, psi_d, psi_q, metadata, notes, warnings)
    i_d, i_q, psi_d, psi_q, said, turned = map_grid.rotate_pm_onto_d(i_d, i_q, psi_d, psi_q, raw.keys[2])
    (notes if turned else warnings).extend([said] if said else [])
    grid = map_grid.rectangular(i_d, i_q, psi_d, psi_q, raw.keys)
    if grid is None:
        pol = map_grid.polar(i_d, i_q, psi_d, psi_q, raw.keys)
        if pol is None:
            raise MapImportError(None, f"{raw.keys[0]}, {raw.keys[1]}", "currents on an i_d x i_q grid (meshgrid or "
                                 "ndgrid) or on a current magnitude x angle grid", "scattered points")
        grid = map_grid.resample_polar(*pol)
    i_d, i_q, psi_d, psi_q, note = grid
    notes += [note] if note else []
    magnet_free = map_grid.magnet_free(i_d, i_q, psi_d, psi_q)
    i_d, i_q, psi_d, psi_q, mirrored, _ = symmetry.complete(i_d, i_q, psi_d, psi_q, magnet_free)
    notes += mirrored
    _check(i_d, i_q, raw.keys)
    _check_metadata(metadata)
    if i_d[-1] <= 0.0:
        warnings.append("no i_d > 0 in the map (a PM machine: no symmetry completes it): where an optimum lies at "
                        "i_d > 0 the FMUs extrapolate beyond the grid")
    return ImportedMap(i_d, i_q, psi_d, psi_q, raw.source_format, notes, metadata, path, warnings)


def _fit_iron_loss(raw, i_d, i_q, psi_d, psi_q, metadata: dict, notes: list, warnings: list) -> None:
    """The contract's iron-loss coefficients from the tool's loss map (iron_loss.py), over the
    points inside I_max (all, without it); the fit's error goes into the metadata and the notes."""
    loss = raw.iron_loss
    if loss["f0"] is None or not loss["f0"] > 0:
        warnings.append("the iron-loss map has no frequency f0: no iron-loss coefficients")
        return
    I = np.hypot(i_d, i_q)
    I_max = metadata.get("I_max_A")
    inside = I <= float(I_max) * (1 + 1e-9) if I_max else np.ones(I.shape, bool)
    fit = iron_loss.fit(np.hypot(psi_d, psi_q), loss["P_h"], loss["P_c"], loss["f0"], inside)
    metadata.update(fit.metadata())
    notes.append(fit.describe())
    if (loss["expH"], loss["expC"]) != (1.0, 2.0):
        warnings.append(f"the loss map scales as f^{loss['expH']:g} (hysteresis) and f^{loss['expC']:g} (eddy), the "
                        f"contract's model as f and f^2: the coefficients hold at {loss['f0']:g} Hz")


def _check(i_d, i_q, keys) -> None:
    """What the FMUs' reader needs beyond the grid: enough points, and zero current inside it."""
    from scenarios.core.fmu_ranges import map_limits
    for k, ax in ((keys[0], i_d), (keys[1], i_q)):
        if len(ax) > map_limits().max_axis:  # a CSV the FMUs would refuse is not written
            raise MapImportError(None, k, f"<= {map_limits().max_axis} grid values (the FMUs' limit)", f"{len(ax)}")
        if len(ax) < map_grid.MIN_POINTS:
            raise MapImportError(None, k, f">= {map_grid.MIN_POINTS} grid values", f"{len(ax)}")
        if not ax[0] <= 0.0 <= ax[-1]:
            raise MapImportError(None, k, "a grid that contains zero current (psi_m = psi_d(0, 0))",
                                 f"{ax[0]:.6g} ... {ax[-1]:.6g} A")


def _check_metadata(metadata: dict) -> None:
    """Metadata the map's readers refuse is never written (scenarios.maps.metadata: the FMUs' rule;
    and each value inside the FMUs' range of its parameter): MapImportError naming the key."""
    from scenarios.core.fmu_ranges import fmu_ranges
    from scenarios.maps.metadata import MetadataError, metadata_keys, metadata_value
    for key, k in metadata_keys().items():
        if key not in metadata:
            continue
        try:
            value = metadata_value(key, str(metadata[key]))
        except MetadataError as e:
            raise MapImportError(None, key, e.expected, repr(e.text)) from None
        r = fmu_ranges().get(k.parameter)
        if r is not None and not ((r.lo is None or value >= r.lo) and (r.hi is None or value <= r.hi)):
            lo, hi = ("-inf" if r.lo is None else f"{r.lo:g}"), ("inf" if r.hi is None else f"{r.hi:g}")
            raise MapImportError(None, key, f"a value in the FMUs' range of {k.parameter}, [{lo}, {hi}]", repr(value))


def write_contract_csv(imported: ImportedMap, out: str | Path) -> Path:
    """Write the map as a contract CSV, atomically: a temporary file beside `out`, then renamed."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    # two-word labels: a one-word 'key: value' line would read as metadata (INTERFACE.md)
    comment = "\n".join([f"Imported by scenarios.maps.importer from {imported.source} ({imported.source_format}).",
                         "Convention = amplitude-invariant dq, peak values, PM flux on +d."] +
                        [f"Import conversion: {n}" for n in imported.notes] +
                        [f"Import warning: {w}" for w in imported.warnings])
    from scenarios.core.boundary import write_atomically  # 0644, a regular file only (docs/inputs.md)
    write_atomically(out, lambda tmp: write_flux_map(tmp, imported.flux_map(), comment))
    return out


# the import cache (keyed by content, owned, optional): scenarios.maps.import_cache
from scenarios.maps.import_cache import cache_dir, contract_csv  # noqa: E402
