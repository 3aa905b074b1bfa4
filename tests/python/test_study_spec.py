"""The study specification (INTERFACE.md, "Study specification (TOML)"): the axes' product, an
explicit run list, and bad specifications named by file and key (exit 2). No cluster."""
import math
import subprocess
import sys

import pytest

from scenarios.core.paths import ROOT
from scenarios.study import SpecError, load_spec
from scenarios.study.spec import T_DEFAULT_DEGC

from conftest import patient


def write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_product_of_the_axes_in_order(tmp_path):
    spec = load_spec(write(tmp_path, """
[study]
cycles = ["wltc3b", "UDDS"]
window_s = [10.0, 20.0]
methods = ["ferrari", "lut_flux"]
recursions = 1
u_dc_scale = [1.0, 0.85]
T_magnet_degC = [20, 120.0]
"""))
    assert len(spec.runs) == 2 * 2 * 2 * 2
    first, last = spec.runs[0], spec.runs[-1]
    assert (first.cycle, first.method, first.recursion, first.u_dc_scale, first.T_magnet_degC) == \
        ("WLTC3b", "ferrari", 1, 1.0, 20.0)
    assert (last.cycle, last.method, last.u_dc_scale, last.T_magnet_degC) == ("UDDS", "lut_flux", 0.85, 120.0)
    assert first.window == (10.0, 20.0) and first.T_winding_degC == T_DEFAULT_DEGC and first.drive == ""
    # the last axis varies fastest
    assert [r.T_magnet_degC for r in spec.runs[:2]] == [20.0, 120.0]


def test_table_grids_axis(tmp_path):
    spec = load_spec(write(tmp_path, '[study]\nmethods = "lut_flux"\nlut_grids = [[41, 41], [11, 21]]\n'))
    assert [r.lut_grid for r in spec.runs] == [(41, 41), (11, 21)]
    assert load_spec(write(tmp_path, '[study]\nlut_grids = [11, 21]\n')).runs[0].lut_grid == (11, 21)
    assert load_spec(write(tmp_path, '[[run]]\nlut_grid = [5, 7]\n[[run]]\n')).runs[1].lut_grid is None


def test_conditions_are_named_as_the_compare_study_names_them(tmp_path):
    spec = load_spec(write(tmp_path, """
[[run]]
u_dc_scale = 0.85
[[run]]
T_magnet_degC = 120.0
T_winding_degC = 120.0
[[run]]
T_magnet_degC = 60.0
"""))
    names = [r.conditions().name for r in spec.runs]
    assert names[:2] == ["u_dc -15 %", "magnets 120 degC"]
    assert "60" in names[2]
    assert all(math.isnan(r.window_start_s) for r in spec.runs)


def test_csv_cycle_relative_to_the_spec(tmp_path):
    (tmp_path / "c.csv").write_text("time_s,speed_mps\n0,0\n10,5\n")
    spec = load_spec(write(tmp_path, '[study]\ncycles = ["c.csv"]\n'))
    assert spec.runs[0].cycle == str((tmp_path / "c.csv").resolve())


@pytest.mark.parametrize("text, key", [
    ('[study]\nmethod = ["ferrari"]\n', "study.method"),
    ('[study]\nmethods = ["newton"]\n', "study.methods"),
    ('[study]\nrecursions = [3]\n', "study.recursions"),
    ('[study]\nrecursions = [1.5]\n', "study.recursions"),
    ('[study]\nu_dc_scale = ["high"]\n', "study.u_dc_scale"),
    ('[study]\nu_dc_scale = []\n', "study.u_dc_scale"),
    ('[study]\nT_magnet_degC = [-300.0]\n', "study.T_magnet_degC"),
    ('[study]\nwindow_s = [5.0]\n', "study.window_s"),
    ('[study]\nlut_grids = [[41, 2]]\n', "study.lut_grids"),
    ('[study]\nlut_grids = [[41, 41, 41]]\n', "study.lut_grids"),
    ('[[run]]\nlut_grid = 41\n', "run[0].lut_grid"),
    ('[study]\nwindow_s = [5.0, 99999.0]\n', "study.window_s"),
    ('[study]\ncycles = ["nowhere.csv"]\n', "study.cycles"),
    ('[study]\ndrives = ["missing.toml"]\n', "study.drives"),
    ('[studies]\n', "studies"),
    ('[study]\nmethods = ["ferrari"]\n[[run]]\nmethod = "ferrari"\n', "study.methods"),
    ('[[run]]\nmethods = "ferrari"\n', "run[0].methods"),
    ('[[run]]\nmethod = "ferrari"\n[[run]]\nmethod = "ferrari"\n', "run"),
])
def test_bad_spec_names_file_and_key(tmp_path, text, key):
    p = write(tmp_path, text)
    with pytest.raises(SpecError) as e:
        load_spec(p)
    assert str(e.value).startswith(f"{p}: {key}:"), str(e.value)


def test_cli_exit_2_on_a_bad_spec(tmp_path):
    p = write(tmp_path, '[study]\nmethods = ["newton"]\n')
    r = subprocess.run([sys.executable, "-m", "scenarios", "study", str(p), "--out", str(tmp_path / "o")],
                       cwd=ROOT, capture_output=True, text=True, timeout=patient(60))
    assert r.returncode == 2
    assert f"{p}: study.methods" in r.stderr
    assert not (tmp_path / "o").exists()
    r = subprocess.run([sys.executable, "-m", "scenarios", "study", str(tmp_path / "none.toml")],
                       cwd=ROOT, capture_output=True, text=True, timeout=patient(60))
    assert r.returncode == 2 and "No such file or directory" in r.stderr


def test_progress_line():
    import io

    from scenarios.study.progress import StudyProgress
    buf = io.StringIO()
    p = StudyProgress(total=10, skipped=4, stream=buf, every_s=0.0)
    p.update(done=2, failed=1, running=2)
    line = buf.getvalue().strip()
    assert line.startswith("study: 7/10 done (4 before, 1 failed), 2 running,") and line.endswith("left")
    assert "?" not in line  # time left known after the first finished run
