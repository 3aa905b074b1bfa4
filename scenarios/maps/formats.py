"""What the FEM tools' flux-map files hold, read as they are: the field names, units and grid
layouts of each format, and nothing of the conversion to the contract (that is map_grid.py).

SyR-e (https://github.com/SyR-e/syre_public, Apache-2.0):
  `fdfq_idiq_n256.mat` holds top-level `Id`, `Iq`, `Fd`, `Fq` (and `T`, `dT`, ...), written by
  syreManipulateMM / plot_singm.m after `[Id,Iq] = meshgrid(i_d, i_q)`: MATLAB meshgrid layout,
  i_d along the columns (axis 1), i_q along the rows (axis 0); peak A and Vs. The motor-model
  file (e.g. THOR.mat) holds the same four fields in `motorModel.FluxMap_dq`, which is what
  motulator's `import_syre_data` reads (motulator/drive/utils/_flux_maps.py). SyR-e draws
  synchronous-reluctance machines in its "SR" axis convention: PM flux on -q, and usually only
  i_d >= 0 (a half map); its "PM" convention (IPMs) has the PM on +d.
Motor-CAD (Ansys), the Lab "Saturation and Loss Map" export (.mat):
  `Id_Peak`, `Iq_Peak` (A, 2-D, the grid points), `Flux_Linkage_D`, `Flux_Linkage_Q` (Vs,
  averaged over rotor position; `Angular_Flux_Linkage_D/Q` hold them per position along a
  third axis), computed over `Stator_Current_Phase_Peak` x `Phase_Advance` (the default, a
  magnitude x angle grid; MathWorks' getFemPmsmParams.m reads it so) or over d/q currents
  (`Id_Peak[i, j]`: i_d along axis 0, as pymotorcad's ECE example reads it). Lab exports
  also name RMS currents `Id_RMS`, `Iq_RMS`, `Stator_Current_Phase_RMS`. Optional:
  `Phase_Resistance_DC_at_20C` (Ohm), `Frequency` (Hz) and `Speed` (r/min) give R_s and the
  pole pairs.
PLECS (Plexim), the look-up-table layout of its "Look-up table based PMSM" demo:
  `imd` (1 x n_d), `imq` (1 x n_q) the current axes (peak A), `Psid`, `Psiq` (n_d x n_q, Vs):
  rows i_d, columns i_q (PLECS' 2-D look-up table of the demo's model); amplitude-invariant
  dq, PM flux on +d. The file holds no machine data (the demo's model sets pole pairs and R_s).
SyR-e's motor model also holds the machine's data (`motorModel.data`: `p` pole pairs, `Rs`
  Ohm at `tempCu` degC, `i0` rated and `Imax` largest current (peak A), `Vdc` V, `nmax` top
  speed and `n0` base speed (r/min), `P0` rated power (W), `J` rotor inertia (kg m^2), `tempPM`
  degC) and an iron-loss map (`motorModel.IronPMLossMap_dq`, see iron_loss.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenarios.maps.error import MapImportError

SQRT2 = math.sqrt(2.0)  # peak / RMS of a sinusoid
T_20C_K = 293.15        # Motor-CAD's Phase_Resistance_DC_at_20C holds at 20 degC
#: 60 f / n within this (relative) of a whole number: a Frequency written with 6 significant digits
#: (Motor-CAD's Lab export rounds f = p n / 60, e.g. 266.667 Hz at 4000 r/min)
POLE_PAIRS_TOLERANCE = 1e-5


@dataclass
class RawMap:
    """The flux-map samples as a format stores them, in the file's own dq frame, currents
    converted to peak A: i_d, i_q (2-D, or 1-D axes), psi_d, psi_q (2-D, Wb)."""

    source_format: str
    i_d: np.ndarray
    i_q: np.ndarray
    psi_d: np.ndarray
    psi_q: np.ndarray
    keys: tuple            # the file's names of (i_d, i_q, psi_d, psi_q), for messages
    square_axis0: str      # with 1-D axes and a square flux array: which current runs along axis 0
    notes: list = field(default_factory=list)
    metadata: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    iron_loss: dict | None = None  # SyR-e: Id, Iq (its grid), P_h, P_c (W at f0), f0 (Hz), expH, expC


#: bytes a .mat file may hold once its compressed variables are inflated: the FMUs' limit of a
#: flux-map file (scenarios.core.fmu_ranges.map_limits), as four double arrays at most
def _mat_max_bytes() -> int:
    from scenarios.core.fmu_ranges import map_limits
    return map_limits().max_bytes


def _check_mat_size(path: Path, max_bytes: int) -> None:
    """Refuse a .mat file (before scipy reads it) that is not a regular file, is larger than
    `max_bytes`, or whose compressed variables inflate to more: a small file may declare
    gigabytes (zlib compresses zeros 1000:1), and loadmat allocates what it inflates."""
    import stat
    import struct
    import zlib
    try:
        st = path.stat()
    except (OSError, ValueError) as e:
        raise MapImportError(path, "file", "a readable .mat file", f"{e}") from None
    if not stat.S_ISREG(st.st_mode):
        raise MapImportError(path, "file", "a regular file", "a folder, device or pipe")
    if st.st_size > max_bytes:
        raise MapImportError(path, "file", f"a .mat file of at most {max_bytes} bytes", f"{st.st_size} bytes")
    with open(path, "rb") as f:
        head = f.read(128)
        if len(head) < 128 or head[126:128] not in (b"IM", b"MI"):
            return  # not a v5/v7 file (v4 has no compression: its size is its content); loadmat decides
        order = "<" if head[126:128] == b"IM" else ">"
        total = 0
        while True:
            tag = f.read(8)
            if len(tag) < 8:
                return
            dtype, nbytes = struct.unpack(order + "II", tag)
            if dtype >> 16:  # the small data element format: data in the tag's second half
                continue
            if dtype != 15:  # miCOMPRESSED; anything else is in the file, bounded by its size
                f.seek(nbytes + (-nbytes % 8), 1)
                total += nbytes
                continue
            inflate = zlib.decompressobj()
            left = nbytes
            while left > 0:
                chunk = f.read(min(left, 1 << 16))
                if not chunk:
                    break
                left -= len(chunk)
                data = inflate.decompress(chunk, max_bytes + 1 - total)
                total += len(data)
                while inflate.unconsumed_tail and total <= max_bytes:
                    data = inflate.decompress(inflate.unconsumed_tail, max_bytes + 1 - total)
                    total += len(data)
                    if not data:
                        break
                if total > max_bytes:
                    raise MapImportError(path, "file", f"variables of at most {max_bytes} bytes inflated (the FMUs' "
                                         "flux-map limit)", "more: compressed arrays larger than any flux map")


def load_mat(path: Path) -> dict:
    """The variables of a MATLAB .mat file (v4 to v7; v7.3 is HDF5, which scipy.io does not read),
    bounded: see _check_mat_size."""
    from scipy.io import loadmat
    _check_mat_size(path, _mat_max_bytes())
    try:
        return loadmat(str(path), squeeze_me=False, struct_as_record=True)
    except NotImplementedError as e:  # scipy: "Please use HDF reader for matlab v7.3 files"
        raise MapImportError(path, "file", "a MATLAB .mat file of version 7 or older (save with '-v7')",
                             "a v7.3 (HDF5) file") from e
    except Exception as e:  # loadmat raises ValueError, TypeError, OSError... on a file that is not a .mat
        raise MapImportError(path, "file", "a MATLAB .mat file", f"unreadable ({type(e).__name__}: {e})") from e


def _array(path: Path, mat: dict, key: str, label: str) -> np.ndarray:
    if key not in mat:
        raise MapImportError(path, key, f"the variable {key} ({label})", "no such variable")
    kind = np.asarray(mat[key]).dtype.kind
    if kind == "b" or (kind in "iu" and "flux" in label):  # logical, or a flux counted in integers: not Vs
        raise MapImportError(path, key, f"a floating-point array ({label})",
                             f"a {'logical' if kind == 'b' else 'integer'} array ({np.asarray(mat[key]).dtype})")
    if np.iscomplexobj(mat[key]) and np.any(np.imag(mat[key]) != 0):
        raise MapImportError(path, key, f"a real array ({label})", "complex values with a non-zero imaginary part")
    try:
        a = np.asarray(np.real(mat[key]) if np.iscomplexobj(mat[key]) else mat[key], dtype=float)
    except (TypeError, ValueError) as e:
        raise MapImportError(path, key, f"a numeric array ({label})", f"{type(mat[key]).__name__}") from e
    return a


def is_syre(mat: dict) -> bool:
    return {"Id", "Iq", "Fd", "Fq"} <= mat.keys() or "motorModel" in mat


def is_plecs(mat: dict) -> bool:
    return {"imd", "imq", "Psid", "Psiq"} <= mat.keys()


def read_plecs(path: Path, mat: dict) -> RawMap:
    keys = ("imd", "imq", "Psid", "Psiq")
    i_d, i_q, psi_d, psi_q = (_array(path, mat, k, lab) for k, lab in
                              zip(keys, ("d current axis, A peak", "q current axis, A peak", "d flux linkage, Vs",
                                         "q flux linkage, Vs")))
    return RawMap("PLECS", i_d, i_q, psi_d, psi_q, keys, square_axis0="i_d",
                  notes=["PLECS look-up-table fields imd, imq (axes), Psid, Psiq (rows i_d, columns i_q; peak A, Vs)"],
                  warnings=["the PLECS table holds no machine data: pole pairs, R_s, I_max and u_dc come from a "
                            "drive description (or add '# key: value' lines to the CSV)"])


def is_motorcad(mat: dict) -> bool:
    return any(k in mat for k in ("Flux_Linkage_D", "Angular_Flux_Linkage_D", "Id_Peak", "Id_RMS"))


def _struct_field(path: Path, s, name: str, where: str):
    """Field `name` of a loadmat struct (a 1x1 record array)."""
    try:
        return s[name][0, 0]
    except (ValueError, IndexError, KeyError, TypeError) as e:
        raise MapImportError(path, f"{where}.{name}", f"a struct field {where}.{name}", "none") from e


def read_syre(path: Path, mat: dict) -> RawMap:
    if {"Id", "Iq", "Fd", "Fq"} <= mat.keys():
        src, prefix = mat, ""
    else:
        fm = _struct_field(path, mat["motorModel"], "FluxMap_dq", "motorModel")
        src = {k: _struct_field(path, fm, k, "motorModel.FluxMap_dq") for k in ("Id", "Iq", "Fd", "Fq")}
        prefix = "motorModel.FluxMap_dq."
    keys = tuple(prefix + k for k in ("Id", "Iq", "Fd", "Fq"))
    i_d, i_q, psi_d, psi_q = (_array(path, src, k, lab) for k, lab in
                              zip(("Id", "Iq", "Fd", "Fq"), ("d current, A peak", "q current, A peak",
                                                             "d flux linkage, Vs", "q flux linkage, Vs")))
    raw = RawMap("SyR-e", i_d, i_q, psi_d, psi_q, keys, square_axis0="i_q",
                 notes=[f"SyR-e {prefix or 'fdfq_idiq'} fields Id, Iq, Fd, Fq (peak A, Vs)"])
    if prefix:
        _syre_machine_data(path, mat["motorModel"], raw)
    return raw


#: SyR-e motorModel.data field -> (contract metadata key, conversion to SI); every field but the
#: temperatures (degC: zero and below are temperatures too) must be positive
RPM = 2.0 * math.pi / 60.0
ZERO_CELSIUS_K = 273.15
SYRE_DATA = {
    "p": ("pole_pairs", lambda x: x),  # a count: a whole number, checked (never rounded)
    "Rs": ("R_s_ohm", float),
    "tempCu": ("T_winding_ref_K", lambda x: x + ZERO_CELSIUS_K),
    "tempPM": ("T_magnet_ref_K", lambda x: x + ZERO_CELSIUS_K),
    "Imax": ("I_max_A", float),
    "i0": ("I_rated_A", float),
    "Vdc": ("u_dc_V", float),
    "nmax": ("w_m_max_rad_s", lambda x: x * RPM),
    "n0": ("w_m_base_rad_s", lambda x: x * RPM),
    "P0": ("P_rated_W", float),
    "J": ("J_kg_m2", float),
}


SYRE_TEMPERATURES = ("tempCu", "tempPM")


def _syre_scalar(rec, name: str) -> float | None:
    try:
        v = np.asarray(rec[name][0, 0], dtype=float).ravel()
    except (ValueError, IndexError, KeyError, TypeError):
        return None
    return float(v[0]) if v.size and np.isfinite(v[0]) else None


def _syre_field(path: Path, data, name: str) -> float | None:
    """A motorModel.data field (None: absent): one finite number, positive but for a temperature
    (degC, above absolute zero), a whole number for the pole pairs; else MapImportError naming it."""
    try:
        v = np.asarray(data[name][0, 0], dtype=float).ravel()
    except (ValueError, IndexError, KeyError, TypeError):
        return None
    where = f"motorModel.data.{name}"
    if v.size != 1 or not math.isfinite(v[0]):
        raise MapImportError(path, where, "one finite number", f"{v.size} values" if v.size != 1 else repr(v[0].item()))
    x = float(v[0])
    if name in SYRE_TEMPERATURES:
        if x <= -ZERO_CELSIUS_K:
            raise MapImportError(path, where, "a temperature in degC above absolute zero", repr(x))
    elif x <= 0.0:
        raise MapImportError(path, where, "a positive number", repr(x))
    if name == "p" and x != math.floor(x):
        raise MapImportError(path, where, "a whole number of pole pairs", repr(x))
    return x


def _syre_machine_data(path: Path, model, raw: RawMap) -> None:
    """motorModel.data into the contract's metadata, and the iron-loss map for the fit."""
    try:
        data = model["data"][0, 0]
    except (ValueError, IndexError, KeyError, TypeError):
        raw.warnings.append("motorModel.data absent: no machine data (pole pairs, R_s, ratings) carried")
        data = None
    if data is not None:
        got = []
        for field_name, (key, conv) in SYRE_DATA.items():
            x = _syre_field(path, data, field_name)
            if x is not None:
                raw.metadata[key] = int(x) if field_name == "p" else conv(x)
                got.append(f"{field_name} -> {key}")
        raw.notes.append("SyR-e machine data motorModel.data: " + ", ".join(got))
    try:
        loss = model["IronPMLossMap_dq"][0, 0]
        grid = {k: np.asarray(loss[k][0, 0], dtype=float) for k in ("Id", "Iq", "Pfes_h", "Pfes_c", "Pfer_h", "Pfer_c")}
        f0, expH, expC = (_syre_scalar(loss, k) for k in ("f0", "expH", "expC"))
    except (ValueError, IndexError, KeyError, TypeError):
        raw.warnings.append("no iron-loss map (motorModel.IronPMLossMap_dq): no iron-loss coefficients")
        return
    shape = raw.psi_d.shape
    P_h = sum(np.broadcast_to(grid[k], shape) for k in ("Pfes_h", "Pfer_h"))
    P_c = sum(np.broadcast_to(grid[k], shape) for k in ("Pfes_c", "Pfer_c"))
    if grid["Id"].shape != shape or not (np.allclose(grid["Id"], raw.i_d) and np.allclose(grid["Iq"], raw.i_q)):
        raw.warnings.append("the iron-loss map is on another grid than the flux map: no iron-loss coefficients")
        return
    raw.iron_loss = dict(P_h=P_h, P_c=P_c, f0=f0, expH=expH, expC=expC)


def read_motorcad(path: Path, mat: dict) -> RawMap:
    notes = []
    if "Id_Peak" in mat or "Iq_Peak" in mat:
        kd, kq, scale = "Id_Peak", "Iq_Peak", 1.0
    elif "Id_RMS" in mat or "Iq_RMS" in mat:
        kd, kq, scale = "Id_RMS", "Iq_RMS", SQRT2
        notes.append("currents Id_RMS, Iq_RMS converted to peak (x sqrt 2)")
    else:
        raise MapImportError(path, "Id_Peak", "the variables Id_Peak and Iq_Peak (or Id_RMS and Iq_RMS)",
                             "neither")
    i_d = scale * _array(path, mat, kd, "d current")
    i_q = scale * _array(path, mat, kq, "q current")
    fluxes = []
    for axis in "DQ":
        key = f"Flux_Linkage_{axis}"
        if key in mat:
            fluxes.append((key, _array(path, mat, key, f"{axis.lower()} flux linkage, Vs")))
            continue
        angular = f"Angular_{key}"
        if angular not in mat:
            raise MapImportError(path, key, f"the variable {key} (or {angular})", "neither")
        a = _array(path, mat, angular, f"{axis.lower()} flux linkage over rotor position, Vs")
        if a.ndim != 3:
            raise MapImportError(path, angular, "a 3-D array (current grid x rotor position)", f"shape {a.shape}")
        fluxes.append((key, a.mean(axis=2)))
        notes.append(f"{key} = the mean of {angular} over its {a.shape[2]} rotor positions")
    notes.insert(0, f"Motor-CAD fields {kd}, {kq}, Flux_Linkage_D, Flux_Linkage_Q")
    raw = RawMap("Motor-CAD", i_d, i_q, fluxes[0][1], fluxes[1][1], (kd, kq, fluxes[0][0], fluxes[1][0]),
                 square_axis0="i_d", notes=notes)
    raw.metadata.update(_motorcad_metadata(path, mat))
    return raw


def _scalar(mat: dict, key: str) -> float | None:
    try:
        v = np.asarray(mat[key], dtype=float).ravel()
    except (KeyError, TypeError, ValueError):
        return None
    return float(v[0]) if v.size and np.isfinite(v[0]) else None


def _positive(path: Path, mat: dict, key: str, unit: str) -> float | None:
    """A scalar the file gives (None: absent): one finite positive number, else MapImportError
    naming it (a vector of several values is not reduced to one of them)."""
    if key not in mat:
        return None
    try:
        v = np.asarray(mat[key], dtype=float).ravel()
    except (TypeError, ValueError):
        v = np.array([])
    if v.size > 1:
        raise MapImportError(path, key, f"one number ({unit}), the export's single operating point",
                             f"{v.size} values")
    if not v.size or not math.isfinite(v[0]) or v[0] <= 0.0:
        raise MapImportError(path, key, f"a finite positive number ({unit})",
                             repr(v[0].item()) if v.size else "no number")
    return float(v[0])


def _motorcad_metadata(path: Path, mat: dict) -> dict:
    """The contract's '# key: value' metadata a Lab export gives: pole pairs from f = p n / 60, R_s.
    Frequency and Speed must then be finite and positive and give a whole number of pole pairs in
    the FMUs' range (their pole_pairs parameter); an export that does not is refused, naming the
    field, rather than imported without its machine."""
    from scenarios.core.fmu_ranges import fmu_ranges
    md = {}
    f, n = _positive(path, mat, "Frequency", "Hz"), _positive(path, mat, "Speed", "r/min")
    if f is not None and n is not None:
        p = f * 60.0 / n
        r = fmu_ranges().get("pole_pairs")
        lo, hi = (r.lo or 1.0, r.hi or math.inf) if r is not None else (1.0, math.inf)
        whole = math.isfinite(p) and abs(p - round(p)) <= POLE_PAIRS_TOLERANCE * max(1.0, p)
        if not whole or not lo <= round(p) <= hi:
            raise MapImportError(path, "Frequency", f"an electrical frequency that makes 60 f / Speed a whole number "
                                 f"of pole pairs in [{lo:g}, {hi:g}]", f"{f!r} Hz at {n!r} r/min: {p:.6g}")
        md["pole_pairs"] = int(round(p))
    r = _scalar(mat, "Phase_Resistance_DC_at_20C")
    if r and r > 0:
        md["R_s_ohm"] = r
        md["T_winding_ref_K"] = T_20C_K
    return md
