"""`python -m scenarios map show` (issue 15, item 3): on the default map and a saturating one, the
PNG and the Markdown are written, and the Markdown's numbers agree with independent values: the
peak torque at base speed and at the top speed with the brute-force optimum (brute_force.py:
dense sampling + SLSQP on scipy's splines, sharing no code with the controller); reciprocity ~0
on maps reciprocal by construction and the known mismatch on a deliberately non-reciprocal one."""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
import scipy.io as sio

from scenarios.__main__ import main as cli
from scenarios.maps.flux_map import DEFAULT_MAP, FluxMap, read_flux_map, write_flux_map
from scenarios.maps.show import reciprocity
from tools.saturating_map import SaturatingMachine, make_map

from brute_force import Drive, max_torque

TORQUE_TOL = 1e-3       # relative: the controller's optimum against the brute-force one (issue 12's)
RECIPROCAL_REL = 1e-4   # the spline derivatives of a map reciprocal by construction (measured <= 6e-6)
WALL_BUDGET_S = 20.0    # the "fast" (measured ~3 s on a shared 2-core machine)


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    d = tmp_path_factory.mktemp("maps")
    write_flux_map(d / "saturating.csv", make_map(SaturatingMachine(0.3, 0.5, 0.15)))
    return {"default": DEFAULT_MAP, "saturating": d / "saturating.csv"}


@pytest.fixture
def show(controller_fmu):
    """show(args) -> the exit status of `python -m scenarios --build <the FMUs under test> map show args`."""
    build = controller_fmu.parent.parent
    return lambda args: cli(["--build", str(build), "map", "show", *args])


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("IPMSM_MAP_CACHE", str(tmp_path / "cache"))


def md_value(md: str, label: str) -> str:
    m = re.search(rf"^\| {re.escape(label)} \| (.+?) \|$", md, re.M)
    assert m, f"no row '{label}' in map.md"
    return m.group(1)


def brute_T_max(fmap: FluxMap, s: dict, w_m: float) -> float:
    p = s["parameters"]
    d = Drive(fmap, p["pole_pairs"], p["R_s"], p["I_max"], s["V_max_V"], w_m * p["pole_pairs"])
    return max_torque(d, +1.0)[0]


@pytest.mark.parametrize("name", ["default", "saturating"])
def test_show_writes_png_and_markdown_with_numbers_that_hold(show, maps, tmp_path, name):
    out = tmp_path / "show"
    assert show([str(maps[name]), "--out", str(out)]) == 0
    png = (out / "map.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 50_000
    md = (out / "map.md").read_text()
    s = json.loads((out / "map.json").read_text())
    # the Markdown shows the summary's numbers
    assert md_value(md, "peak torque at base speed") == f"{s['T_at_base_Nm']:.2f} N m"
    assert md_value(md, "peak torque (T_max at standstill)") == f"{s['T_peak_Nm']:.2f} N m"
    assert md_value(md, "reciprocity max abs(dpsi_d/di_q - dpsi_q/di_d)").startswith(
        f"{s['reciprocity_max_H'] * 1e6:.4g} uH")
    # ... and they hold against the brute-force optimum
    fmap = read_flux_map(maps[name])
    for w, T in ((0.0, s["T_peak_Nm"]), (s["w_base_rad_s"], s["T_at_base_Nm"]),
                 (s["w_top_rad_s"], s["envelope"]["T_max_Nm"][-1])):
        ref = brute_T_max(fmap, s, w)
        assert T == pytest.approx(ref, rel=TORQUE_TOL), (w, T, ref)
    assert s["w_base_rad_s"] > 0 and s["T_at_base_Nm"] >= 0.99 * s["T_peak_Nm"]
    assert s["reciprocity_rel"] < RECIPROCAL_REL  # both maps are reciprocal by construction
    assert s["mtpv_points"] > 0                   # both reach MTPV within 12 000 r/min
    assert 0.9 < s["eta_max"] < 0.99              # motor + inverter of a 100 kW traction drive
    # the default map carries its whole data sheet; the saturating one all but iron-loss data
    # the saturating test map has a data sheet but no iron loss: only that is assumed (named per coefficient)
    assert s["assumed"] == ([] if name == "default" else [a for a in s["assumed"] if a.startswith("fe_")])
    assert s["wall_s"] < WALL_BUDGET_S


def test_reciprocity_is_zero_on_a_reciprocal_map_and_the_mismatch_on_a_non_reciprocal_one():
    f = make_map(SaturatingMachine(0.3, 0.5, 0.15))
    _, abs_0, rel_0, _ = reciprocity(f, 500.0)
    assert rel_0 < RECIPROCAL_REL
    c = 5e-5  # H: psi_q += c i_d makes dpsi_q/di_d exceed dpsi_d/di_q by c everywhere
    I_d, _ = np.meshgrid(f.i_d, f.i_q, indexing="ij")
    bent = FluxMap(f.i_d, f.i_q, f.psi_d, f.psi_q + c * I_d, f.metadata)
    mismatch, abs_1, rel_1, _ = reciprocity(bent, 500.0)
    assert abs_1 == pytest.approx(c, rel=1e-3) and rel_1 > 100 * RECIPROCAL_REL
    assert np.allclose(mismatch, -c, atol=abs_0 + 1e-9)


def test_show_on_a_non_reciprocal_map_reports_its_mismatch(show, maps, tmp_path):
    """5e-5 H also folds the map at high i_q, beyond the drive's operating region (|i_q| > 550 A
    of a 500 A machine): both FMUs accept it with a warning (docs/maps.md, "Where a map must be
    legal") and the plant inverts its positive-definite continuation there, so everything is
    shown, the efficiency map included."""
    f = read_flux_map(maps["saturating"])
    c = 5e-5
    I_d, _ = np.meshgrid(f.i_d, f.i_q, indexing="ij")
    write_flux_map(tmp_path / "bent.csv", FluxMap(f.i_d, f.i_q, f.psi_d, f.psi_q + c * I_d, f.metadata))
    assert show([str(tmp_path / "bent.csv"), "--out", str(tmp_path / "o")]) == 0
    md = (tmp_path / "o" / "map.md").read_text()
    assert md_value(md, "reciprocity max abs(dpsi_d/di_q - dpsi_q/di_d)").startswith("50 uH")
    assert md_value(md, "peak efficiency (motor + inverter)").endswith(" N m")
    assert (tmp_path / "o" / "map.png").stat().st_size > 50_000


def test_show_takes_a_fem_export_and_gives_the_csv_s_numbers(show, maps, tmp_path):
    """A SyR-e half map (PM on -q) of the default motor: the same machine as its CSV. The .mat has no
    metadata: the FMUs' defaults (the default motor's) are assumed and listed."""
    f = read_flux_map(maps["default"])
    jq = f.i_q >= 0
    Id, Iq = np.meshgrid(f.i_q[jq], -f.i_d[::-1])
    sio.savemat(tmp_path / "fdfq_idiq_n256.mat", dict(Id=Id, Iq=Iq, Fd=f.psi_q[::-1][:, jq], Fq=-f.psi_d[::-1][:, jq]))
    assert show([str(tmp_path / "fdfq_idiq_n256.mat"), "--u-dc", "355", "--I-max", "500",
                "--out", str(tmp_path / "m")]) == 0
    assert show([str(maps["default"]), "--out", str(tmp_path / "c")]) == 0
    a, b = (json.loads((tmp_path / d / "map.json").read_text()) for d in ("m", "c"))
    assert a["T_peak_Nm"] == pytest.approx(b["T_peak_Nm"], rel=1e-9)
    assert a["P_max_W"] == pytest.approx(b["P_max_W"], rel=1e-3)  # top speed: metadata vs 4 x base speed
    assert not any("I_max" in x for x in a["assumed"])  # given on the command line
    assert "assumed: pole_pairs" in (tmp_path / "m" / "map.md").read_text()


def test_show_of_a_bad_file_exits_2_and_writes_nothing(show, tmp_path, capsys):
    (tmp_path / "bad.mat").write_bytes(b"not a mat file")
    assert show([str(tmp_path / "bad.mat"), "--out", str(tmp_path / "o")]) == 2
    assert "bad.mat: file: expected a MATLAB .mat file" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_envelope_power_is_torque_times_speed(show, maps, tmp_path):
    assert show([str(maps["default"]), "--out", str(tmp_path / "o")]) == 0
    e = json.loads((tmp_path / "o" / "map.json").read_text())["envelope"]
    assert np.allclose(np.array(e["T_max_Nm"]) * np.array(e["speed_rad_s"]), e["P_W"], rtol=1e-12)
    assert math.isclose(max(e["P_W"]), json.loads((tmp_path / "o" / "map.json").read_text())["P_max_W"])


def test_show_on_the_measured_map(show, tmp_path):
    """The real measured map (not reciprocal, no I_max in its metadata): shown, its mismatch
    reported as found, its peak torque the brute-force optimum's."""
    from scenarios.core.paths import DATA_DIR
    path = DATA_DIR / "fluxmaps" / "baldor_5p6kW_pmsyrm_measured.csv"
    assert show([str(path), "--out", str(tmp_path / "o")]) == 0
    s = json.loads((tmp_path / "o" / "map.json").read_text())
    assert s["u_dc_V"] == 540.0 and s["parameters"]["I_max"] == 20.0  # metadata; the grid's reach
    assert any(a.startswith("I_max = 20 A") for a in s["assumed"])
    assert s["reciprocity_rel"] > 10 * RECIPROCAL_REL  # measured: 0.84 %
    fmap = read_flux_map(path)
    for w, T in ((0.0, s["T_peak_Nm"]), (s["w_top_rad_s"], s["envelope"]["T_max_Nm"][-1])):
        assert T == pytest.approx(brute_T_max(fmap, s, w), rel=TORQUE_TOL)
