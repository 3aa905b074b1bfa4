"""Real maps as published (issue 23): `map check` (legal domain, reciprocity, noise, I_max, the FMUs'
own verdict), `map repair` (crop, projection, symmetry, holes; every change stated), the importers
keeping what the FEM tool knows (SyR-e machine data and iron-loss fit, the PLECS table layout),
machine parameters named where assumed, and the top speed flagged."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.io as sio

from scenarios.__main__ import main as cli
from scenarios.core.paths import DATA_DIR
from scenarios.maps import legal
from scenarios.maps.flux_map import DEFAULT_MAP, FluxMap, read_flux_map, write_flux_map
from scenarios.maps.fmu_verdict import verdict
from scenarios.maps.importer import import_map
from tools.saturating_map import SaturatingMachine, make_map

REAL = DATA_DIR / "fluxmaps" / "real"
PRIUS_CSV = REAL / "plecs_prius_as_published.csv"
PRIUS_MAT = REAL / "plecs_prius_lut.mat"
RAWP = REAL / "syre_RAWP.mat"


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("IPMSM_MAP_CACHE", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def build(controller_fmu):
    return controller_fmu.parent.parent


def _accepted_by_all(csv, build, **params) -> list:
    return [verdict(build / "fmu" / f"{n}.fmu", csv, params) for n in ("IpmsmController", "IpmsmPlant", "IpmsmDrive")]


# --- importers ------------------------------------------------------------------------------

def test_syre_import_keeps_the_machine_data_and_states_the_iron_loss_fit():
    m = import_map(RAWP)
    md = m.flux_map().metadata
    mat = sio.loadmat(RAWP, squeeze_me=True, struct_as_record=False)["motorModel"]
    data = mat.data
    assert int(md["pole_pairs"]) == data.p == 3
    assert float(md["R_s_ohm"]) == pytest.approx(data.Rs, rel=1e-12)
    assert float(md["I_max_A"]) == data.Imax and float(md["u_dc_V"]) == data.Vdc
    assert float(md["w_m_max_rad_s"]) == pytest.approx(data.nmax * math.pi / 30, rel=1e-12)
    assert float(md["T_winding_ref_K"]) == pytest.approx(data.tempCu + 273.15)
    # the fit's error, recomputed here from the loss map and the stated coefficients
    loss = mat.IronPMLossMap_dq
    F = mat.FluxMap_dq
    P = loss.Pfes_h + loss.Pfer_h + loss.Pfes_c + loss.Pfer_c
    inside = np.hypot(F.Id, F.Iq) <= data.Imax
    b = np.hypot(F.Fd, F.Fq)[inside] / float(md["fe_psi_ref_Wb"])
    f0 = float(loss.f0)
    model = float(md["fe_k_h_W_per_Hz"]) * f0 * b ** float(md["fe_alpha"]) + \
        float(md["fe_k_e_W_per_Hz2"]) * f0 ** 2 * b ** 2
    err = np.abs(model - P[inside]).max() / P[inside].max()
    assert float(md["fe_fit_max_error_rel"]) == pytest.approx(err, rel=1e-3)
    assert any("fit error max" in n for n in m.notes)
    # a magnet-free quarter map: mirrored in i_q and in i_d, no warning about i_d > 0 left
    assert m.i_d[0] == -m.i_d[-1] and m.i_q[0] == -m.i_q[-1]
    assert not any("no i_d > 0" in w for w in m.warnings)
    k = len(m.i_d) // 2
    assert m.i_d[k] == 0 and np.array_equal(m.psi_d[:k], -m.psi_d[:k:-1]) and np.array_equal(m.psi_q[:k],
                                                                                             m.psi_q[:k:-1])


def test_plecs_table_layout_read_and_the_published_csv_keeps_its_pole_pairs():
    lut = import_map(PRIUS_MAT)
    csv = import_map(PRIUS_CSV)
    assert lut.source_format == "PLECS" and (len(lut.i_d), len(lut.i_q)) == (41, 21)
    assert np.array_equal(lut.i_d, csv.i_d) and np.array_equal(lut.i_q, csv.i_q)
    assert np.abs(lut.psi_d - csv.psi_d).max() < 1e-12 and np.abs(lut.psi_q - csv.psi_q).max() < 1e-12
    assert any("no machine data" in w for w in lut.warnings)  # the table has none: said, not invented
    assert csv.flux_map().number("pole_pairs") == 4 and csv.flux_map().number("R_s_ohm") == 0.015


def test_magnet_free_quarter_csv_completed_by_symmetry(tmp_path):
    """A SyRM's first-quadrant map (i_d <= 0, i_q >= 0 here) gives back the whole machine."""
    sm = SaturatingMachine(0.6, 0.8, 0.2)
    full = make_map(sm)
    full = FluxMap(full.i_d, full.i_q, full.psi_d - full.psi_d[len(full.i_d) // 2, len(full.i_q) // 2], full.psi_q)
    # a magnet-free machine's symmetry made exact (the test machine has a magnet: remove and symmetrise)
    pd = 0.5 * (full.psi_d - full.psi_d[::-1])
    pd = 0.5 * (pd + pd[:, ::-1])
    pq = 0.5 * (full.psi_q + full.psi_q[::-1])
    pq = 0.5 * (pq - pq[:, ::-1])
    full = FluxMap(full.i_d, full.i_q, pd, pq)
    jd, jq = full.i_d <= 0, full.i_q >= 0
    write_flux_map(tmp_path / "quarter.csv", FluxMap(full.i_d[jd], full.i_q[jq], pd[jd][:, jq], pq[jd][:, jq]))
    m = import_map(tmp_path / "quarter.csv")
    assert np.allclose(m.i_d, full.i_d) and np.allclose(m.i_q, full.i_q)
    assert np.abs(m.psi_d - pd).max() < 1e-12 and np.abs(m.psi_q - pq).max() < 1e-12
    said = " ".join(m.notes)
    assert "mirrored about the d axis" in said and "mirrored about the q axis" in said


# --- check -------------------------------------------------------------------------------------

def _same_box_as_the_fmus(fmap, I_max: float, fmu_log: list) -> None:
    """legal.refused_box (the Python side's statement of operating_region.hpp's rule) is the box
    the FMUs name in their own refusal or warning, to the 6 digits they print it with."""
    import re
    said = [re.search(r"widened by [0-9.]+ % of I_max: i_d in \[(\S+), (\S+)\] A, i_q in \[(\S+), (\S+)\] A", m)
            for m in fmu_log]
    boxes = {m.groups() for m in said if m}
    assert boxes == {tuple(f"{x:.6g}" for x in legal.refused_box(fmap, I_max))}, (boxes, fmu_log)


def test_check_reports_the_prius_defects_and_the_fmus_own_verdict(build, tmp_path):
    out = tmp_path / "chk"
    status = cli(["--build", str(build), "map", "check", str(PRIUS_CSV), "--out", str(out)])
    c = json.loads((out / "check.json").read_text())
    truth = [(v.accepted, v.verdict) for v in _accepted_by_all(PRIUS_CSV, build, pole_pairs=4, R_s=0.015,
                                                                 I_max=200.0)]
    assert [(f["accepted"], f["verdict"]) for f in c["fmus"]] == truth
    # psi_d falls at i_d = 130 ... 140 A, outside the operating region: accepted with one warning
    assert all(v == (True, "accepted with a warning") for v in truth) and status == 0
    assert c["verdict"] == "accept it with a warning"
    assert "FMUs accept it with a warning" in (out / "check.md").read_text()
    for f in c["fmus"]:
        warned = [m for m in f["log"] if m.startswith("warning:") and "not legal at" in m]
        assert len(warned) == 1 and "i_d = 130 A" in warned[0], f["log"]  # where, in the FMU's words
        assert "widened by 10 % of I_max" in warned[0]  # the FMI logger's printf escape undone
        _same_box_as_the_fmus(read_flux_map(PRIUS_CSV), c["I_max_A"], f["log"])
    assert all(d["within_drive_currents"] == 0 for d in c["defects"])  # all at i_d > 0
    assert all(d["within_refused_box"] == 0 for d in c["defects"])  # the FMUs' own count: they accept
    falls = next(d for d in c["defects"] if d["kind"].startswith("psi_d"))
    assert falls["count"] == 2 and falls["nearest_A"] == [135.0, -20.0]  # between 130 and 140 A, i_q = +-20 A
    assert c["grid_covers_I_max"] and c["legal_rectangle_A"][1] < 130 and c["I_max_A"] == 200.0
    assert 0 < c["noise_Wb"]["psi_d"] < 1e-2 and "## The FMUs' verdict" in (out / "check.md").read_text()


def test_a_map_folding_inside_the_operating_region_is_refused_naming_where(build, tmp_path):
    f = read_flux_map(DEFAULT_MAP)
    j = int(np.argmin(np.abs(f.i_d + 100.0)))
    k = int(np.argmin(np.abs(f.i_q - 200.0)))
    psi_d = f.psi_d.copy()
    psi_d[j, k] = psi_d[j + 1, k] + 1e-3   # psi_d falls with i_d there
    write_flux_map(tmp_path / "bad.csv", FluxMap(f.i_d, f.i_q, psi_d, f.psi_q, f.metadata))
    out = tmp_path / "chk"
    assert cli(["--build", str(build), "map", "check", str(tmp_path / "bad.csv"), "--out", str(out)]) == 1
    c = json.loads((out / "check.json").read_text())
    assert not any(x["accepted"] for x in c["fmus"])
    assert sum(d["within_refused_box"] for d in c["defects"]) > 0  # the FMUs' own rule, counted
    for x in c["fmus"]:
        _same_box_as_the_fmus(read_flux_map(tmp_path / "bad.csv"), c["I_max_A"], x["log"])
    assert all(f"i_d = {f.i_d[j + 1]:g} A" in " ".join(x["log"]) or f"i_q = {f.i_q[k]:g} A" in " ".join(x["log"])
               for x in c["fmus"])
    assert c["legal_rectangle_A"] is None  # no crop holds the drive's currents


# --- repair ------------------------------------------------------------------------------------

def test_repair_prius_crops_without_changing_a_value_and_the_fmus_accept(build, tmp_path, capsys):
    out = tmp_path / "prius.csv"
    assert cli(["--build", str(build), "map", "repair", str(PRIUS_CSV), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "cropped" in said and "no value changed" in said
    r, o = read_flux_map(out), read_flux_map(PRIUS_CSV)
    a = int(np.searchsorted(o.i_d, r.i_d[0]))
    assert r.i_d[-1] == 90.0 and np.array_equal(r.psi_d, o.psi_d[a:a + len(r.i_d)]) and r.metadata["pole_pairs"] == "4"
    assert "Repair change: cropped" in out.read_text()


def test_repair_rawp_as_published_accepted(build, tmp_path):
    out = tmp_path / "rawp.csv"
    assert cli(["--build", str(build), "map", "repair", str(RAWP), "--out", str(out)]) == 0
    r = read_flux_map(out)
    assert r.i_q[-1] >= 30.0 and r.i_d[-1] >= 30.0 and r.metadata["pole_pairs"] == "3"
    assert not legal.defects(r).count()


def test_repair_completes_a_circle_only_measurement_and_a_quarter_map(build, tmp_path, capsys):
    """Made for the test from a known machine (the default motor): NaN outside |i| = 450 A of its
    500 A map, and its motoring quadrant only; both repaired maps are accepted, the given points
    unchanged, the made points counted."""
    f = read_flux_map(DEFAULT_MAP)
    I_d, I_q = np.meshgrid(f.i_d, f.i_q, indexing="ij")
    outside = np.hypot(I_d, I_q) > 450.0
    lines = [f"# {k}: {v}" for k, v in f.metadata.items()] + ["i_d,i_q,psi_d,psi_q"]
    for a, x in enumerate(f.i_d):
        for b, y in enumerate(f.i_q):
            pd, pq = ("nan", "nan") if outside[a, b] else (f"{f.psi_d[a, b]:.15g}", f"{f.psi_q[a, b]:.15g}")
            lines.append(f"{x:.12g},{y:.12g},{pd},{pq}")
    (tmp_path / "circle.csv").write_text("\n".join(lines) + "\n")
    assert cli(["--build", str(build), "map", "repair", str(tmp_path / "circle.csv"), "--out",
                str(tmp_path / "c.csv")]) == 0
    assert f"{int(outside.sum())} points without a value" in capsys.readouterr().out
    r = read_flux_map(tmp_path / "c.csv")  # (cropped where the extension folds, beyond I_max)
    ja, ka = np.searchsorted(f.i_d, r.i_d), np.searchsorted(f.i_q, r.i_q)
    given = ~outside[np.ix_(ja, ka)]
    assert np.array_equal(r.psi_d[given], f.psi_d[np.ix_(ja, ka)][given]) and r.i_q[-1] >= 500.0
    jq = f.i_q >= 0
    write_flux_map(tmp_path / "quarter.csv", FluxMap(f.i_d, f.i_q[jq], f.psi_d[:, jq], f.psi_q[:, jq], f.metadata))
    assert cli(["--build", str(build), "map", "repair", str(tmp_path / "quarter.csv"), "--out",
                str(tmp_path / "q.csv")]) == 0
    q = read_flux_map(tmp_path / "q.csv")
    assert np.abs(q.psi_d - f.psi_d).max() < 1e-12  # the default motor is symmetric about d


# --- machine parameters ------------------------------------------------------------------------

def test_no_iron_loss_metadata_no_crash_and_map_show_agrees_with_the_drive(tmp_path):
    """A magnet-free map without iron-loss metadata: fe_psi_ref is never psi_m = 0, and `map show`
    and a drive description take the same named values."""
    from scenarios.drives.description import load_drive
    from scenarios.maps.flux_map import linear_flux_map
    from scenarios.maps.show import machine_parameters
    f = linear_flux_map(2e-3, 8e-3, 0.0, 60.0, n=25, pole_pairs="3", R_s_ohm="0.4", I_max_A="40")
    write_flux_map(tmp_path / "syrm.csv", f)
    (tmp_path / "d.toml").write_text('[motor]\nflux_map = "syrm.csv"\n')
    d = load_drive(tmp_path / "d.toml")
    params, assumed, _ = machine_parameters(read_flux_map(tmp_path / "syrm.csv"), None)
    for k in ("fe_k_h", "fe_alpha", "fe_k_e", "fe_psi_ref", "pole_pairs", "R_s", "I_max"):
        assert params[k] == getattr(d.motor, k)
    assert d.motor.fe_psi_ref > 0 and any("fe_psi_ref" in a for a in d.assumed) and assumed
    assert d.motor.pole_pairs == 3 and not any(a.startswith("pole_pairs") for a in d.assumed)


# --- top speed -----------------------------------------------------------------------------------

def test_top_speed_flagged_and_gated(tmp_path, controller_fmu, plant_fmu):
    """The default car with its top speed set below what UDDS's hill (91 km/h) needs: the summary
    counts the time above it, and `check`'s limit on it fails."""
    from scenarios.drives.description import load_drive
    from scenarios.runs.check import judge
    from scenarios.runs.simulate import RunSpec, simulate
    from scenarios.vehicle.cycles import load_cycle, segment
    (tmp_path / "d.toml").write_text(f'[motor]\nflux_map = "{DEFAULT_MAP}"\nw_m_max = 500.0\n'
                                     '[checks]\ntime_above_top_speed_s_max = 0.0\n')
    d = load_drive(tmp_path / "d.toml")
    s = simulate(segment(load_cycle("UDDS"), 180.0, 260.0), RunSpec(drive=d, reference=False),
                 fmus=(controller_fmu, plant_fmu), progress=False).to_dict()
    assert s["w_m_max_rpm"] == pytest.approx(500.0 * 30 / math.pi) and s["w_m_peak_rpm"] > s["w_m_max_rpm"]
    assert s["time_above_top_speed_s"] > 0
    v = judge("UDDS", s, d.checks.limits)[0]  # the drive's one limit (then every check's cycle-following ones)
    assert not v.passed


# --- the SyRM drive end to end -------------------------------------------------------------------

@pytest.fixture(scope="module")
def syrm_drive(build, tmp_path_factory):
    """scenarios/drives/syrm_rawp.toml on RAWP as published: the FMUs accept it with one warning
    (psi_q not monotone at |i_q| >= 47.3 A, beyond I_max)."""
    from scenarios.drives.description import DRIVES_DIR, load_drive
    from scenarios.maps.importer import contract_csv
    d = tmp_path_factory.mktemp("syrm")
    import os
    os.environ.setdefault("IPMSM_MAP_CACHE", str(d / "cache"))
    m = load_drive(DRIVES_DIR / "syrm_rawp.toml")
    found = _accepted_by_all(contract_csv(RAWP), build, **m.plant_params())
    assert all(v.verdict == "accepted with a warning" for v in found), [(v.fmu, v.log) for v in found]
    return m


def _syrm_run(drive, cycle, t0, t1, controller_fmu, plant_fmu):
    from scenarios.drives.description import load_drive
    from scenarios.runs.check import judge
    from scenarios.runs.simulate import RunSpec, simulate
    from scenarios.vehicle.cycles import load_cycle, segment
    c = load_cycle(cycle)
    c = c if t1 is None else segment(c, t0, t1)
    s = simulate(c, RunSpec(drive=drive), fmus=(controller_fmu, plant_fmu), progress=False).to_dict()
    limits = {k: v for k, v in load_drive(None).checks.limits.items() if k.startswith("torque")}
    return s, judge(cycle, s, limits)


def test_a_top_speed_limit_without_a_top_speed_is_refused_and_never_passes(tmp_path):
    """No w_m_max anywhere (the Baldor map says none): the limit could measure nothing, so the
    description is refused at load, and a summary without the figure fails the limit."""
    from scenarios.drives.description import DriveDescriptionError, load_drive
    from scenarios.runs.check import judge
    measured = DATA_DIR / "fluxmaps" / "baldor_5p6kW_pmsyrm_measured.csv"
    (tmp_path / "d.toml").write_text(f'[motor]\nflux_map = "{measured}"\n'
                                     '[checks]\ntime_above_top_speed_s_max = 0.0\n')
    with pytest.raises(DriveDescriptionError, match="checks.time_above_top_speed_s_max"):
        load_drive(tmp_path / "d.toml")
    v = judge("X", {"time_above_top_speed_s": None}, {"time_above_top_speed_s_max": 0.0})[0]
    assert not v.passed


@pytest.mark.parametrize("cycle, t0, t1", [("UDDS", 180.0, 290.0), ("HWFET", 0.0, 100.0)])
def test_syrm_drive_segments_within_the_default_torque_limits(syrm_drive, controller_fmu, plant_fmu, cycle, t0, t1):
    s, verdicts = _syrm_run(syrm_drive, cycle, t0, t1, controller_fmu, plant_fmu)
    assert all(v.passed for v in verdicts), [v.message for v in verdicts]
    assert s["time_above_top_speed_s"] == 0.0 and s["speed_rmse_mps"] < 0.2


@pytest.mark.slow
@pytest.mark.parametrize("cycle", ["UDDS", "HWFET"])
def test_syrm_drive_whole_cycles_within_the_default_torque_limits(syrm_drive, controller_fmu, plant_fmu, cycle):
    s, verdicts = _syrm_run(syrm_drive, cycle, 0.0, None, controller_fmu, plant_fmu)
    assert all(v.passed for v in verdicts), [v.message for v in verdicts]


def test_run_picture_draws_the_drives_own_motor():
    """run.png's current plane: the drive's current limit and voltage ellipses at its top speed, not
    the default motor's 500 A and 12 000 r/min."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from scenarios.drives.description import DRIVES_DIR, load_drive
    from scenarios.runs.plots import _current_plane
    d = load_drive(DRIVES_DIR / "prius.toml")
    tr = {"i_d_A": np.array([-20.0, -40.0]), "i_q_A": np.array([50.0, 80.0]), "region": np.array([1, 1]),
          "u_dc_V": np.array([500.0, 500.0]), "w_m_rad_s": np.array([100.0, 200.0])}
    fig, a = plt.subplots()
    _current_plane(a, tr, d)
    labels = [line.get_label() for line in a.get_lines()]
    plt.close(fig)
    assert "current limit 200 A" in labels and "voltage limit 6000 r/min, 500 V" in labels


def test_check_json_is_strict_when_a_figure_is_undefined(build, tmp_path):
    """A 4 x 4 grid has no noise estimate (too few points per axis): check.json says null, never
    NaN, and every strict reader takes it."""
    i_d, i_q = np.array([-300.0, -200.0, -100.0, 0.0]), np.array([-300.0, -150.0, 0.0, 150.0])
    D, Q = np.meshgrid(i_d, i_q, indexing="ij")
    write_flux_map(tmp_path / "m.csv", FluxMap(i_d, i_q, 0.1 + 2e-4 * D, 4e-4 * Q), "a 4 x 4 linear machine")
    assert cli(["--build", str(build), "map", "check", str(tmp_path / "m.csv"), "--out", str(tmp_path / "o"),
                "--I-max", "100"]) == 0
    text = (tmp_path / "o" / "check.json").read_text()

    def refuse(c):
        raise ValueError(c)
    doc = json.loads(text, parse_constant=refuse)
    assert None in doc["noise_Wb"].values()


def test_repair_reads_within_the_limits_and_names_the_bad_line(build, tmp_path, capsys):
    """A comment that happens to contain "nan" and a malformed row: exit 2 naming the line, as
    `map check` does (never the holes reader's own unbounded parse)."""
    text = "# author: Hernandez\ni_d,i_q,psi_d,psi_q\n0,0,0.1,0\n0;x\n"
    (tmp_path / "m.csv").write_text(text)
    assert cli(["--build", str(build), "map", "repair", str(tmp_path / "m.csv"), "--out", str(tmp_path / "o.csv")]) == 2
    assert "line 4" in capsys.readouterr().err


# --- a repair that verifies what it writes (issue 35, finding 4) -----------------------------------

def test_repair_refuses_a_sign_error_naming_it_and_writes_nothing(build, tmp_path, capsys):
    """The default map with psi_q negated: a projection would change 3570 of 3621 points (L_q
    0.57 mH -> 2.7e-10 H) and every FMU would accept the result; the repair is refused instead."""
    fmap = read_flux_map(DEFAULT_MAP)
    bad = tmp_path / "psi_q_negated.csv"
    write_flux_map(bad, FluxMap(fmap.i_d, fmap.i_q, fmap.psi_d, -fmap.psi_q, fmap.metadata))
    out = tmp_path / "repaired.csv"
    assert cli(["--build", str(build), "map", "repair", str(bad), "--out", str(out)]) == 2
    said = capsys.readouterr().err
    assert str(bad) in said and "psi_q has the wrong sign?" in said, said
    assert not out.exists() and not list(tmp_path.glob(".repaired*"))


def test_repair_with_i_max_writes_it_and_its_output_is_accepted_everywhere(build, tmp_path, capsys):
    """--I-max 200 crops to 200 A: the output says I_max_A: 200 (not the source's 500), so that
    map check, run and map show accept it."""
    fmap = read_flux_map(DEFAULT_MAP)
    # a fold beyond 250 A (the repair crops it away) in an otherwise good map
    psi_q = fmap.psi_q.copy()
    far = np.hypot(*np.meshgrid(fmap.i_d, fmap.i_q, indexing="ij")) > 400.0
    psi_q[far & (fmap.i_q[None, :] > 0)] *= 0.2
    src = tmp_path / "folded.csv"
    write_flux_map(src, FluxMap(fmap.i_d, fmap.i_q, fmap.psi_d, psi_q, fmap.metadata))
    out = tmp_path / "repaired.csv"
    code = cli(["--build", str(build), "map", "repair", str(src), "--out", str(out), "--I-max", "200"])
    said = capsys.readouterr()
    assert code == 0, said
    assert read_flux_map(out).metadata["I_max_A"] == "200"
    assert "short simulation" not in said.out  # it ran, and passed
    assert cli(["--build", str(build), "map", "check", str(out), "--out", str(tmp_path / "check")]) == 0
    assert cli(["--build", str(build), "map", "show", str(out), "--out", str(tmp_path / "show")]) == 0
    drive = tmp_path / "drive.toml"
    drive.write_text(f'name = "repaired"\n[motor]\nflux_map = "{out}"\n')
    cycle = tmp_path / "gentle.csv"
    cycle.write_text("time_s,speed_mps\n" + "".join(f"{t},{min(t, 4) * 0.5}\n" for t in range(0, 7)))
    assert cli(["run", str(cycle), "--drive", str(drive), "--out", str(tmp_path / "run")]) == 0


def test_repair_writes_nothing_when_the_short_simulation_fails(build, tmp_path, monkeypatch, capsys):
    """The FMUs' acceptance is not enough: the repaired map is simulated before it is written."""
    import scenarios.maps.repair as repair
    monkeypatch.setattr(repair, "short_simulation", lambda *a: ["w_m = 0 rad/s: CVODE too much work (made up)"])
    out = tmp_path / "repaired.csv"
    assert cli(["--build", str(build), "map", "repair", str(DEFAULT_MAP), "--out", str(out)]) == 1
    said = capsys.readouterr().out
    assert "short simulation (IpmsmDrive): w_m = 0 rad/s" in said and "not written" in said
    assert not out.exists()
