"""One version number everywhere: pyproject.toml's is every FMU's `version` attribute (CMake reads
it), `python -m scenarios --version`, the wheel's, the `version` of summary.json and of every
runs.parquet row (failed ones too), and CHANGELOG.md has a section for it."""
from __future__ import annotations

import json
import re
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description

from scenarios.core.paths import ROOT
from scenarios.core.version import VERSION

from conftest import BUILD_FMU, fmu_path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

FMUS = ("IpmsmController", "IpmsmPlant", "IpmsmDrive")


def test_the_one_version_is_pyproject_s():
    assert VERSION == tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert re.fullmatch(r"\d+\.\d+\.\d+", VERSION), VERSION
    assert f"\n## {VERSION}\n" in (ROOT / "CHANGELOG.md").read_text()


@pytest.mark.parametrize("name", FMUS)
def test_every_fmu_carries_it(name):
    assert read_model_description(str(fmu_path(name))).version == VERSION


def test_the_ssp_package_s_fmus_carry_it():
    with zipfile.ZipFile(BUILD_FMU.parent / "ssp" / "IpmsmControllerPlant.ssp") as z:
        for name in ("IpmsmController", "IpmsmPlant"):
            with z.open(f"resources/{name}.fmu") as f, zipfile.ZipFile(f) as fmu:
                assert f'version="{VERSION}"' in fmu.read("modelDescription.xml").decode()


def test_the_command_line_prints_it():
    out = subprocess.run([sys.executable, "-m", "scenarios", "--version"], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == f"ipmsm-fmu {VERSION}"


def test_a_summary_and_every_runs_parquet_row_carry_it(tmp_path, controller_fmu, plant_fmu):
    from scenarios.runs.simulate import RunSpec, simulate
    from scenarios.study.spec import Run
    from scenarios.study.table import SCHEMA, row_of, summary_of
    from scenarios.vehicle.cycles import Cycle

    cycle = Cycle("ramp", np.array([0.0, 1.0]), np.array([0.0, 1.0]))  # 1 s: what is checked is the record, not the run
    s = simulate(cycle, RunSpec(backend="drive", reference=False), fmus=(controller_fmu, plant_fmu), out=tmp_path,
                 progress=False)
    assert json.loads((tmp_path / "summary.json").read_text())["version"] == VERSION
    assert "version" in SCHEMA.names
    ok = row_of(Run(), {"status": "ok"}, s)
    assert ok["version"] == VERSION and summary_of(ok).version == VERSION
    assert row_of(Run(), {"status": "failed"}, None)["version"] == VERSION
