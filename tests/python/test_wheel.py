"""The wheel (build/dist/ipmsm_fmu-<version>-py3-none-any.whl; cmake/wheel.cmake,
tools/wheel/make_wheel.py).

- Its content (cheap): the scenarios package with its data, the three FMUs as built, FMI 2.0 and
  FMI 3.0 (Linux and, unless the build was told IPMSM_WIN64=OFF, Windows binaries inside each),
  the SSP package, the default map, the coupling description and the efficiency map the plots
  draw; nothing compiled outside the FMUs; the native master's sources not at all.
- slow: installed into a fresh venv in a temporary folder (pip from the registry, or with
  IPMSM_WHEELHOUSE=DIR from that folder of wheels only), run from another folder with no
  repository in reach: `--version`, `fmu-path` (and `--fmi 3`), a standard cycle (UDDS on the
  drive backend), `check` and `map show` give the repository's results (the summaries equal but
  for the wall time; check.md and map.md equal).
"""
from __future__ import annotations

import io
import json
import os
import posixpath
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

from scenarios.core.paths import PACKAGE_DIR, ROOT, SHIPPED
from scenarios.core.version import VERSION

from conftest import BUILD_FMU, BUILD_FMU3, WIN64_BUILT

WHEEL = BUILD_FMU.parent / "dist" / f"ipmsm_fmu-{VERSION}-py3-none-any.whl"
FMUS = ("IpmsmController", "IpmsmPlant", "IpmsmDrive")
#: what may differ between two runs of the same cycle
TIMINGS = ("wall_s", "real_time_factor")

pytestmark = pytest.mark.skipif(os.environ.get("IPMSM_UNDER_SANITIZER") == "1",
                                reason="the sanitizer build makes no wheel: its FMUs are not for shipping")


@pytest.fixture(scope="module")
def wheel() -> zipfile.ZipFile:
    if not WHEEL.exists():
        pytest.fail(f"{WHEEL} is missing: build it (cmake --build build --target wheel)")
    with zipfile.ZipFile(WHEEL) as z:
        yield z


def _package_files() -> set[str]:
    """The repository's package files the wheel must hold: modules and data, no native/."""
    out = set()
    for p in PACKAGE_DIR.rglob("*"):
        rel = p.relative_to(PACKAGE_DIR.parent)
        if p.is_file() and "__pycache__" not in rel.parts and rel.parts[1] != "native" and p.name != "README.md":
            out.add(rel.as_posix())
    return out


def test_the_wheel_holds_the_package_and_its_data(wheel):
    names = set(wheel.namelist())
    missing = _package_files() - names
    assert not missing, sorted(missing)[:10]
    assert not [n for n in names if n.startswith("scenarios/native/")]
    assert not [n for n in names if n.endswith((".so", ".dll", ".pyd", ".dylib"))]  # compiled code: in FMUs only
    meta = wheel.read(f"ipmsm_fmu-{VERSION}.dist-info/METADATA").decode()
    assert f"\nVersion: {VERSION}\n" in meta
    assert "Tag: py3-none-any" in wheel.read(f"ipmsm_fmu-{VERSION}.dist-info/WHEEL").decode()


def test_the_wheel_holds_the_built_fmus_the_ssp_and_the_files_they_read(wheel):
    for rel in SHIPPED:
        parts = Path(rel).parts
        built = BUILD_FMU.parent.joinpath(*parts[1:]) if parts[0] == "build" else ROOT / rel
        assert wheel.read(f"scenarios/shipped/{rel}") == built.read_bytes(), rel
    osp = ET.fromstring(wheel.read("scenarios/cosim/osp/OspSystemStructure.xml"))
    for sim in osp.iter("{http://opensimulationplatform.com/MSMI/OSPSystemStructure}Simulator"):
        assert posixpath.normpath(posixpath.join("scenarios/cosim/osp", sim.get("source"))) in wheel.namelist()
    for name in FMUS:  # FMI 2.0's platform folders, and FMI 3.0's
        for folder, linux, windows in (("fmu", "linux64", "win64"), ("fmu3", "x86_64-linux", "x86_64-windows")):
            with zipfile.ZipFile(io.BytesIO(wheel.read(f"scenarios/shipped/build/{folder}/{name}.fmu"))) as fmu:
                binaries = set(fmu.namelist())
            assert f"binaries/{linux}/{name}.so" in binaries
            assert (f"binaries/{windows}/{name}.dll" in binaries) == WIN64_BUILT


# --- installed ---

def _run(cmd, cwd, env, timeout=900) -> subprocess.CompletedProcess:
    r = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert r.returncode in (0, 1), f"{cmd}: exit {r.returncode}\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}"
    return r


def _untimed(markdown: str) -> str:
    """A report without its wall time (map.md ends with one)."""
    return re.sub(r"(?i)wall time [0-9.]+ s", "wall time _ s", markdown)


def _summary(path: Path) -> dict:
    s = json.loads(path.read_text())
    return {k: v for k, v in s.items() if k not in TIMINGS}


@pytest.mark.slow
def test_the_installed_wheel_runs_from_another_folder_as_the_repository(wheel, tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "IPMSM_FMU_DIR")}
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    py = str(venv / "bin" / "python")
    source = (["--no-index", "--find-links", os.environ["IPMSM_WHEELHOUSE"]] if os.environ.get("IPMSM_WHEELHOUSE")
              else [])
    subprocess.run([py, "-m", "pip", "install", "--quiet", *source, str(WHEEL)], check=True, env=env, timeout=1800)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()

    where = _run([py, "-c", "import scenarios; print(scenarios.__file__)"], elsewhere, env).stdout.strip()
    assert Path(where).is_relative_to(venv), where  # the installed copy, not the repository
    assert _run([py, "-m", "scenarios", "--version"], elsewhere, env).stdout.strip() == f"ipmsm-fmu {VERSION}"
    fmu = Path(_run([py, "-m", "scenarios", "fmu-path", "IpmsmDrive"], elsewhere, env).stdout.strip())
    assert fmu.is_relative_to(venv) and fmu.read_bytes() == (BUILD_FMU / "IpmsmDrive.fmu").read_bytes()
    fmu3 = Path(_run([py, "-m", "scenarios", "fmu-path", "IpmsmDrive", "--fmi", "3"], elsewhere, env).stdout.strip())
    assert fmu3.is_relative_to(venv) and fmu3.read_bytes() == (BUILD_FMU3 / "IpmsmDrive.fmu").read_bytes()

    # a standard cycle, from the wheel and from the repository (this interpreter, the build's FMUs)
    _run([py, "-m", "scenarios", "run", "UDDS", "--backend", "drive"], elsewhere, env)
    build = ["--build", str(BUILD_FMU.parent)]
    _run([sys.executable, "-m", "scenarios", *build, "run", "UDDS", "--backend", "drive", "--out",
          str(tmp_path / "repo_run")], ROOT, env)
    got, want = _summary(elsewhere / "out" / "UDDS_ferrari" / "summary.json"), _summary(tmp_path / "repo_run" /
                                                                                        "summary.json")
    assert got == want and got["version"] == VERSION

    # check and map show on a user's drive beside it (a short cycle of its own)
    user = tmp_path / "user"
    user.mkdir()
    shutil.copy(ROOT / "fmu_src" / "resources" / "ev_ipmsm_default.csv", user / "my_motor.csv")
    (user / "short.csv").write_text("time_s,speed_mps\n0,0\n10,8\n20,8\n30,0\n")
    (user / "my_drive.toml").write_text('name = "my_car"\n[motor]\nflux_map = "my_motor.csv"\n[checks]\n'
                                        'cycles = ["short.csv"]\nWh_per_km_max = 150.0\n')
    for py_, cwd, out in ((py, elsewhere, "wheel"), (sys.executable, ROOT, "repo")):
        b = [] if py_ == py else build
        _run([py_, "-m", "scenarios", *b, "check", str(user / "my_drive.toml"), "--backend", "drive",
              "--out", str(tmp_path / out / "check")], cwd, env)
        _run([py_, "-m", "scenarios", *b, "map", "show", str(user / "my_motor.csv"), "--out",
              str(tmp_path / out / "map")], cwd, env)
    for rel in ("check/check.md", "map/map.md"):
        wheel_md, repo_md = ((tmp_path / side / rel).read_text() for side in ("wheel", "repo"))
        assert _untimed(wheel_md) == _untimed(repo_md), rel
