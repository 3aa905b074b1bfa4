"""Flux maps from FEM tools (issue 15, item 2): SyR-e and Motor-CAD .mat files written with
scipy.io from known machines (the default map, a saturating map of tools/saturating_map.py), in
each layout the importer handles (peak and RMS, full and half maps, meshgrid and ndgrid, PM on
-q, phase-advance grids), imported; the controller FMU on the imported CSV must give the same
T_max and current commands as on the original map. Bad files: exit 2, file and field named,
nothing written."""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.io as sio

from scenarios.__main__ import main as cli
from scenarios.cosim.fmu import Fmu
from scenarios.maps.flux_map import FluxMap, read_flux_map, write_flux_map
from scenarios.maps.importer import MapImportError, contract_csv, import_map, write_contract_csv
from tools.saturating_map import SaturatingMachine, make_map

SQRT2 = math.sqrt(2.0)
RPM = 2 * math.pi / 60
# (T_ref N m, speed r/min): MTPA, field weakening, beyond reach (T_max), generating, at 355 V
POINTS = [(50.0, 1000.0), (200.0, 2000.0), (400.0, 3000.0), (150.0, 6000.0), (-150.0, 6000.0),
          (400.0, 9000.0), (80.0, 11000.0)]
# Exact grids: the importer only reorders, negates and scales by sqrt 2; the CSV holds 12 (currents)
# and 15 (fluxes) significant digits, so the controller sees the same map up to rounding.
ROUND_TRIP = 1e-9
SATURATING = SaturatingMachine(0.3, 0.5, 0.15)
MILD = SaturatingMachine(1.0, 0.5, 0.15)  # q saturation at I_max: reluctance torque wants i_d < 0


@pytest.fixture(scope="module")
def known_maps(tmp_path_factory):
    """name -> (FluxMap as written to CSV and read back, the CSV's path)."""
    d = tmp_path_factory.mktemp("known")
    out = {}
    from scenarios.maps.flux_map import DEFAULT_MAP
    out["default"] = (read_flux_map(DEFAULT_MAP), DEFAULT_MAP)
    write_flux_map(d / "saturating.csv", make_map(SATURATING))
    out["saturating"] = (read_flux_map(d / "saturating.csv"), d / "saturating.csv")
    return out


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("IPMSM_MAP_CACHE", str(tmp_path / "cache"))


# --- writers of the FEM layouts, from a contract map f (i_d along axis 0, ascending axes) -------

def syre_sr(f: FluxMap, half: bool, struct: bool = False) -> dict:
    """SyR-e, "SR" axes (PM on -q: Id_syre = i_q, Iq_syre = -i_d, Fd = psi_q, Fq = -psi_d), meshgrid
    layout (Id_syre along the columns), half map Id_syre >= 0 as SyR-e computes synchronous-reluctance
    machines."""
    jq = f.i_q >= 0 if half else np.ones(len(f.i_q), bool)
    Id, Iq = np.meshgrid(f.i_q[jq], -f.i_d[::-1])
    fields = dict(Id=Id, Iq=Iq, Fd=f.psi_q[::-1][:, jq], Fq=-f.psi_d[::-1][:, jq])
    return dict(motorModel=dict(FluxMap_dq=fields)) if struct else fields


def syre_pm(f: FluxMap) -> dict:
    """SyR-e, "PM" axes (IPMs: PM on +d), its meshgrid layout."""
    Id, Iq = np.meshgrid(f.i_d, f.i_q)
    return dict(Id=Id, Iq=Iq, Fd=f.psi_d.T, Fq=f.psi_q.T)


def motorcad_dq(f: FluxMap, rms: bool = False, transposed: bool = False, half: bool = False,
                descending: bool = False) -> dict:
    """Motor-CAD Lab export over d/q currents: Id_Peak[i, j] with i_d along axis 0."""
    jq = f.i_q >= 0 if half else np.ones(len(f.i_q), bool)
    I_d, I_q = np.meshgrid(f.i_d, f.i_q[jq], indexing="ij")
    psi_d, psi_q = f.psi_d[:, jq], f.psi_q[:, jq]
    if descending:
        I_d, I_q, psi_d, psi_q = (a[::-1, ::-1] for a in (I_d, I_q, psi_d, psi_q))
    if transposed:
        I_d, I_q, psi_d, psi_q = I_d.T, I_q.T, psi_d.T, psi_q.T
    cur = dict(Id_RMS=I_d / SQRT2, Iq_RMS=I_q / SQRT2) if rms else dict(Id_Peak=I_d, Iq_Peak=I_q)
    return dict(**cur, Flux_Linkage_D=psi_d, Flux_Linkage_Q=psi_q, Frequency=np.array([[400.0]]),
                Speed=np.array([[6000.0]]), Phase_Resistance_DC_at_20C=np.array([[0.012]]))


def motorcad_phase_advance(machine: SaturatingMachine, n_mag: int, n_angle: int, angular: bool = False) -> dict:
    """Motor-CAD's default export: Stator_Current_Phase_Peak x Phase_Advance (deg, from +q
    towards -d: i_d = -I sin(beta), i_q = I cos(beta)), fluxes from the machine's closed form."""
    R = machine.grid_span_ratio * machine.I_max
    mags = np.linspace(0.0, R, n_mag)
    beta = np.linspace(0.0, 360.0, n_angle)
    I, B = np.meshgrid(mags, beta, indexing="ij")
    I_d, I_q = -I * np.sin(np.radians(B)), I * np.cos(np.radians(B))
    psi_d, psi_q = machine.flux(I_d, I_q)
    out = dict(Stator_Current_Phase_Peak=I, Phase_Advance=B, Id_Peak=I_d, Iq_Peak=I_q)
    if angular:  # per rotor position, the dq fluxes constant over it plus a ripple of mean zero
        ripple = 1e-3 * np.sin(np.linspace(0, 2 * np.pi, 12, endpoint=False))
        out.update(Angular_Flux_Linkage_D=psi_d[..., None] + ripple, Angular_Flux_Linkage_Q=psi_q[..., None] - ripple)
    else:
        out.update(Flux_Linkage_D=psi_d, Flux_Linkage_Q=psi_q)
    return out


def commands(controller_fmu, csv, **params):
    """(T_max, i_d_ref, i_q_ref) of a fresh controller (Ferrari, recursion 2) at POINTS."""
    rows = []
    with Fmu(controller_fmu, flux_map=str(csv), recursion=2, **params) as c:
        for k, (T, n) in enumerate(POINTS):
            c.set(T_ref=T, w_m=n * RPM, u_dc=355.0, T_magnet=293.15, i_d=0.0, i_q=0.0)
            c.step(k * 1e-4, 1e-4)
            rows.append(c.get("T_max", "i_d_ref", "i_q_ref"))
    return np.array(rows)


def _rel(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


LAYOUTS = {
    "syre-SR-half": lambda f: syre_sr(f, half=True),
    "syre-SR-full-struct": lambda f: syre_sr(f, half=False, struct=True),
    "syre-PM": syre_pm,
    "motorcad-peak": motorcad_dq,
    "motorcad-rms": lambda f: motorcad_dq(f, rms=True),
    "motorcad-rms-half-transposed": lambda f: motorcad_dq(f, rms=True, half=True, transposed=True),
    "motorcad-descending": lambda f: motorcad_dq(f, descending=True),
}


@pytest.mark.parametrize("machine", ["default", "saturating"])
@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_layouts_import_to_the_same_grid(known_maps, tmp_path, machine, layout):
    f, _ = known_maps[machine]
    sio.savemat(tmp_path / "map.mat", LAYOUTS[layout](f))
    m = import_map(tmp_path / "map.mat")
    assert np.allclose(m.i_d, f.i_d, rtol=1e-15, atol=0) and np.allclose(m.i_q, f.i_q, rtol=1e-15, atol=0)
    assert _rel(m.psi_d, f.psi_d) < 1e-15 and _rel(m.psi_q, f.psi_q) < 1e-15
    said = " ".join(m.notes)
    assert ("mirrored" in said) == ("half" in layout)
    assert ("turned by 90 deg" in said) == ("SR" in layout)
    assert ("peak (x sqrt 2)" in said) == ("rms" in layout)


@pytest.mark.parametrize("machine", ["default", "saturating"])
@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_controller_on_the_imported_map_gives_the_same_commands(controller_fmu, known_maps, tmp_path, machine,
                                                                 layout):
    f, original = known_maps[machine]
    sio.savemat(tmp_path / "map.mat", LAYOUTS[layout](f))
    imported = contract_csv(tmp_path / "map.mat")
    assert imported != tmp_path / "map.mat" and imported.suffix == ".csv"
    a, b = commands(controller_fmu, imported), commands(controller_fmu, original)
    assert np.all(np.abs(a - b) <= ROUND_TRIP * np.maximum(1.0, np.abs(b))), (a, b)
    assert np.abs(b[:, 0]).min() > 10.0  # the points are real operating points


def test_motorcad_metadata_carried(known_maps, tmp_path):
    sio.savemat(tmp_path / "mc.mat", motorcad_dq(known_maps["default"][0]))
    m = import_map(tmp_path / "mc.mat")
    assert m.metadata == {"pole_pairs": 4, "R_s_ohm": 0.012, "T_winding_ref_K": 293.15}


# Phase-advance grid: 26 magnitudes (25 A steps to 625 A) x 73 angles (5 deg), resampled onto a
# 53 x 53 rectangular grid of 25 A step. Measured on SATURATING (this test's setup): flux error
# 1.3e-5 Wb (0.02 % of psi_m) at worst inside |i| <= I_max; T_max within 6.5e-6 (relative), the
# commands within 0.56 A (0.11 % of I_max: near-flat optima move most).
PHASE_ADVANCE_FLUX_TOL = 1e-4                # Wb, inside the current limit
PHASE_ADVANCE_T_TOL = 1e-4                   # relative, T_max
PHASE_ADVANCE_I_TOL = 2e-3 * SATURATING.I_max  # A, the commands


@pytest.mark.parametrize("angular", [False, True])
def test_phase_advance_grid_resampled_within_the_stated_error(controller_fmu, known_maps, tmp_path, angular):
    sio.savemat(tmp_path / "pa.mat", motorcad_phase_advance(SATURATING, 26, 73, angular=angular))
    m = import_map(tmp_path / "pa.mat")
    assert any("resampled" in n for n in m.notes)
    I_d, I_q = np.meshgrid(m.i_d, m.i_q, indexing="ij")
    inside = np.hypot(I_d, I_q) <= SATURATING.I_max
    psi_d, psi_q = SATURATING.flux(I_d, I_q)
    err = max(np.abs(m.psi_d - psi_d)[inside].max(), np.abs(m.psi_q - psi_q)[inside].max())
    assert err < PHASE_ADVANCE_FLUX_TOL, err
    out = write_contract_csv(m, tmp_path / "pa.csv")
    a, b = commands(controller_fmu, out), commands(controller_fmu, known_maps["saturating"][1])
    assert _rel(a[:, 0], b[:, 0]) < PHASE_ADVANCE_T_TOL
    assert np.abs(a[:, 1:] - b[:, 1:]).max() < PHASE_ADVANCE_I_TOL


def test_phase_advance_resampling_error_falls_with_the_grid_step():
    """The stated error is the interpolation's, not a bias: halving the step cuts it ~16x (cubic)."""
    errs = []
    for n_mag, n_ang in ((14, 37), (27, 73)):
        import tempfile
        from pathlib import Path
        with tempfile.TemporaryDirectory() as d:
            sio.savemat(Path(d) / "pa.mat", motorcad_phase_advance(SATURATING, n_mag, n_ang))
            m = import_map(Path(d) / "pa.mat")
        I_d, I_q = np.meshgrid(m.i_d, m.i_q, indexing="ij")
        inside = np.hypot(I_d, I_q) <= SATURATING.I_max
        errs.append(np.abs(m.psi_q - SATURATING.flux(I_d, I_q)[1])[inside].max())
    assert errs[1] < errs[0] / 4, errs


def test_contract_csv_returns_a_good_csv_as_is_and_caches_imports(known_maps, tmp_path):
    f, original = known_maps["saturating"]
    assert contract_csv(original) == original
    f_neg = FluxMap(f.i_d[f.i_d <= 0], f.i_q, f.psi_d[f.i_d <= 0], f.psi_q[f.i_d <= 0])  # legal, with a warning
    write_flux_map(tmp_path / "neg.csv", f_neg)
    assert contract_csv(tmp_path / "neg.csv") == tmp_path / "neg.csv"
    sio.savemat(tmp_path / "m.mat", motorcad_dq(f, rms=True))
    first = contract_csv(tmp_path / "m.mat")
    mtime = first.stat().st_mtime_ns
    assert contract_csv(tmp_path / "m.mat") == first and first.stat().st_mtime_ns == mtime  # cached
    sio.savemat(tmp_path / "m.mat", motorcad_dq(f, rms=False))
    assert contract_csv(tmp_path / "m.mat") != first  # new content, new import
    # a half-map CSV is not a contract map: imported (mirrored) too
    half = FluxMap(f.i_d, f.i_q[f.i_q >= 0], f.psi_d[:, f.i_q >= 0], f.psi_q[:, f.i_q >= 0])
    write_flux_map(tmp_path / "half.csv", half)
    full = read_flux_map(contract_csv(tmp_path / "half.csv"))
    assert np.allclose(full.i_q, f.i_q) and _rel(full.psi_q, f.psi_q) < 1e-14


def test_cli_import_writes_the_csv_and_states_the_conversions(known_maps, tmp_path, capsys):
    sio.savemat(tmp_path / "fdfq_idiq_n256.mat", syre_sr(known_maps["default"][0], half=True))
    assert cli(["map", "import", str(tmp_path / "fdfq_idiq_n256.mat"), "--out", str(tmp_path / "o.csv")]) == 0
    text = (tmp_path / "o.csv").read_text()
    assert "# Import conversion: PM flux found on -q" in text and "# Import conversion: half map" in text
    assert read_flux_map(tmp_path / "o.csv").metadata == {}  # the conversions are not read as metadata
    assert "mirrored" in capsys.readouterr().out


# --- bad files: (file content maker, the field the message must name) ----------------------------

def _bad(f: FluxMap) -> dict:
    good = motorcad_dq(f)
    nan = dict(good, Flux_Linkage_D=good["Flux_Linkage_D"].copy())
    nan["Flux_Linkage_D"][3, 4] = np.nan
    swapped = dict(good, Id_Peak=good["Id_Peak"].copy())
    swapped["Id_Peak"][[5, 6], :] = swapped["Id_Peak"][[6, 5], :]  # i_d axis out of order
    skew = motorcad_dq(f)
    c, s = math.cos(math.radians(45)), math.sin(math.radians(45))  # PM at 45 deg: not a dq map
    skew["Flux_Linkage_D"], skew["Flux_Linkage_Q"] = (c * good["Flux_Linkage_D"] - s * good["Flux_Linkage_Q"],
                                                      s * good["Flux_Linkage_D"] + c * good["Flux_Linkage_Q"])
    scattered = dict(good, Id_Peak=good["Id_Peak"] + np.random.default_rng(1).normal(0, 1, good["Id_Peak"].shape))
    no_zero = motorcad_dq(FluxMap(f.i_d[f.i_d < -1], f.i_q, f.psi_d[f.i_d < -1], f.psi_q[f.i_d < -1]))
    syre = syre_sr(f, half=True, struct=True)
    del syre["motorModel"]["FluxMap_dq"]["Fq"]
    return {
        "missing-field": ({k: v for k, v in good.items() if k != "Flux_Linkage_Q"}, "Flux_Linkage_Q"),
        "missing-struct-field": (syre, "motorModel.FluxMap_dq.Fq"),
        "wrong-shape": (dict(good, Flux_Linkage_Q=good["Flux_Linkage_Q"][:, :-1]), "Flux_Linkage_Q"),
        "nan": (nan, "Flux_Linkage_D"),
        "non-monotonic": (swapped, "Id_Peak"),
        "pm-off-axis": (skew, "Flux_Linkage_D"),
        "scattered": (scattered, "Id_Peak, Iq_Peak"),
        "no-zero-current": (no_zero, "Id_Peak"),
        "unknown-variables": (dict(foo=np.ones((3, 3))), "variables"),
    }


BAD = ["missing-field", "missing-struct-field", "wrong-shape", "nan", "non-monotonic", "pm-off-axis", "scattered",
       "no-zero-current", "unknown-variables"]


@pytest.mark.parametrize("kind", BAD)
def test_bad_mat_file_exit_2_names_file_and_field_writes_nothing(known_maps, tmp_path, capsys, kind):
    content, key = _bad(known_maps["default"][0])[kind]
    sio.savemat(tmp_path / "bad.mat", content)
    out = tmp_path / "out" / "map.csv"
    assert cli(["map", "import", str(tmp_path / "bad.mat"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "bad.mat") in err and f": {key}: expected" in err, err
    assert not out.exists() and not (out.parent.exists() and any(out.parent.iterdir()))
    with pytest.raises(MapImportError) as e:
        import_map(tmp_path / "bad.mat")
    assert e.value.key == key and e.value.file == tmp_path / "bad.mat" and e.value.expected


@pytest.mark.parametrize("name, content, key", [
    ("text.mat", b"i_d,i_q,psi_d,psi_q\n", "file"),
    ("map.txt", b"whatever", "file"),
    ("nan.csv", b"i_d,i_q,psi_d,psi_q\n" + b"".join(f"{a},{b},{'nan' if a == b == 1 else 0.1},0\n".encode()
                                                     for a in range(-2, 3) for b in range(-2, 3)), "psi_d"),
    ("header.csv", b"id,iq,psid,psiq\n0,0,0.1,0\n", "rows"),
    ("missing.mat", None, "file"),
])
def test_bad_files_of_other_kinds(tmp_path, capsys, name, content, key):
    if content is not None:
        (tmp_path / name).write_bytes(content)
    out = tmp_path / "o.csv"
    assert cli(["map", "import", str(tmp_path / name), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / name) in err and f": {key}: expected" in err, err
    assert not out.exists()


@pytest.mark.parametrize("quarter_turns", [1, 2, 3])
def test_pm_on_any_axis_is_turned_onto_plus_d(known_maps, tmp_path, quarter_turns):
    """The same machine drawn with its PM on +q, -d or -q (the frame turned by k x 90 deg)."""
    f, _ = known_maps["default"]
    r = 1j**quarter_turns
    I_d, I_q = np.meshgrid(f.i_d, f.i_q, indexing="ij")
    i, psi = (I_d + 1j * I_q) * r, (f.psi_d + 1j * f.psi_q) * r
    sio.savemat(tmp_path / "m.mat", dict(Id_Peak=i.real, Iq_Peak=i.imag, Flux_Linkage_D=psi.real,
                                         Flux_Linkage_Q=psi.imag))
    m = import_map(tmp_path / "m.mat")
    assert f"found on {('+d', '+q', '-d', '-q')[quarter_turns]}" in " ".join(m.notes)
    assert np.allclose(m.i_d, f.i_d, rtol=0, atol=1e-12) and np.allclose(m.i_q, f.i_q, rtol=0, atol=1e-12)
    assert _rel(m.psi_d, f.psi_d) < 1e-15 and _rel(m.psi_q, f.psi_q) < 1e-15


@pytest.mark.parametrize("machine", ["default", "saturating"])
def test_one_dimensional_axes_in_either_orientation(known_maps, tmp_path, machine):
    """Id and Iq as vectors: the flux arrays' shape says the orientation; a square grid takes the
    format's own (Motor-CAD: i_d along the rows), and says so."""
    f, _ = known_maps[machine]
    for psi_d, psi_q in ((f.psi_d, f.psi_q), (f.psi_d.T, f.psi_q.T)):
        sio.savemat(tmp_path / "m.mat", dict(Id_Peak=f.i_d, Iq_Peak=f.i_q, Flux_Linkage_D=psi_d, Flux_Linkage_Q=psi_q))
        m = import_map(tmp_path / "m.mat")
        square = len(f.i_d) == len(f.i_q)
        if square and psi_d is not f.psi_d:
            assert _rel(m.psi_d, f.psi_d.T) < 1e-15  # ambiguous: read as Motor-CAD writes, not guessed
        else:
            assert _rel(m.psi_d, f.psi_d) < 1e-15 and _rel(m.psi_q, f.psi_q) < 1e-15
        assert any("square grid" in n for n in m.notes) == square


def test_phase_advance_quarter_map_motoring_only(controller_fmu, tmp_path):
    """Advance 0 ... 90 deg only (i_d <= 0, i_q >= 0, the motoring quadrant a FEM run often covers):
    the sector is resampled, then mirrored to i_q < 0; generating points come from the mirror.
    A machine whose optimum lies at i_d < 0 (MILD): nothing can complete i_d > 0 (no symmetry in d;
    on SATURATING, whose peak torque lies at i_d > 0, the controller extrapolates: +2 %)."""
    write_flux_map(tmp_path / "mild.csv", make_map(MILD))
    data = motorcad_phase_advance(MILD, 26, 73)
    quarter = {k: v[:, :19] for k, v in data.items()}  # beta 0 ... 90 deg in 5 deg steps
    sio.savemat(tmp_path / "q.mat", quarter)
    m = import_map(tmp_path / "q.mat")
    said = " ".join(m.notes)
    assert "resampled" in said and "mirrored" in said and "no i_d > 0" in " ".join(m.warnings)
    assert m.i_d[-1] == 0.0 and m.i_q[0] == -m.i_q[-1]
    I_d, I_q = np.meshgrid(m.i_d, m.i_q, indexing="ij")
    inside = np.hypot(I_d, I_q) <= MILD.I_max
    psi_d, psi_q = MILD.flux(I_d, I_q)
    assert max(np.abs(m.psi_d - psi_d)[inside].max(), np.abs(m.psi_q - psi_q)[inside].max()) < PHASE_ADVANCE_FLUX_TOL
    a = commands(controller_fmu, write_contract_csv(m, tmp_path / "q.csv"))
    b = commands(controller_fmu, tmp_path / "mild.csv")
    assert _rel(a[:, 0], b[:, 0]) < PHASE_ADVANCE_T_TOL
    assert np.abs(a[:, 1:] - b[:, 1:]).max() < PHASE_ADVANCE_I_TOL
    assert (b[:, 1] < 0).all()  # the premise: every optimum at i_d < 0


@pytest.mark.parametrize("convention", ["SR", "PM"])
def test_synchronous_reluctance_map_without_pm(controller_fmu, tmp_path, convention):
    """No PM flux: the axes are told by saliency. In SyR-e's SR convention (d = high inductance)
    the frame turns so that d is the low-inductance axis, as the contract's IPMSM frame."""
    from scenarios.maps.flux_map import linear_flux_map
    f = linear_flux_map(2e-4, 6e-4, 0.0, 700.0, n=29)
    write_flux_map(tmp_path / "syrm.csv", f)
    content = syre_sr(f, half=True) if convention == "SR" else syre_pm(f)
    sio.savemat(tmp_path / "syrm.mat", content)
    m = import_map(tmp_path / "syrm.mat")
    assert np.allclose(m.i_d, f.i_d, rtol=0, atol=1e-12) and np.allclose(m.i_q, f.i_q, rtol=0, atol=1e-12)
    assert _rel(m.psi_d, f.psi_d) < 1e-15 and _rel(m.psi_q, f.psi_q) < 1e-15
    said = " ".join(m.notes + m.warnings)
    assert ("turned by 90 deg" in said) == (convention == "SR") and "no PM flux" in said
    assert np.array_equal(commands(controller_fmu, contract_csv(tmp_path / "syrm.mat")),
                          commands(controller_fmu, tmp_path / "syrm.csv"))
    assert contract_csv(tmp_path / "syrm.csv") == tmp_path / "syrm.csv"  # a warning changes nothing


def test_phase_advance_grid_without_zero_current_is_refused(tmp_path):
    data = motorcad_phase_advance(SATURATING, 26, 73)
    sio.savemat(tmp_path / "pa.mat", {k: v[1:] for k, v in data.items()})
    with pytest.raises(MapImportError, match="current magnitudes from 0 A"):
        import_map(tmp_path / "pa.mat")


def test_phase_advance_grid_rounded_to_seven_digits(tmp_path):
    """An export that rounds (7 significant digits) still reads as a magnitude x angle grid."""
    data = motorcad_phase_advance(SATURATING, 26, 73)
    rounded = {k: np.array([float(f"{x:.7g}") for x in v.ravel()]).reshape(v.shape) for k, v in data.items()}
    sio.savemat(tmp_path / "pa.mat", rounded)
    m = import_map(tmp_path / "pa.mat")
    I_d, I_q = np.meshgrid(m.i_d, m.i_q, indexing="ij")
    inside = np.hypot(I_d, I_q) <= SATURATING.I_max
    psi_d, psi_q = SATURATING.flux(I_d, I_q)
    assert max(np.abs(m.psi_d - psi_d)[inside].max(), np.abs(m.psi_q - psi_q)[inside].max()) < PHASE_ADVANCE_FLUX_TOL
