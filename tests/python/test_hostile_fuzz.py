"""A fuzz of the drive-description loader over its schema (issue 24): every key of SCHEMA with
every hostile value (huge and tiny numbers, NaN, Inf, wrong types, NUL, an unknown user's home,
huge strings, nested tables) loads or raises DriveDescriptionError naming the file and that key,
never another exception. The default run takes a value sample per key; @slow takes them all.

And IpmsmDrive's bounded step: a communication step of more than max_samples_per_step sample
times is refused with fmi2Error at once, and the instance steps normally afterwards."""
from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import pytest

from scenarios.drives.description import FAULT_TRIGGERS, SCHEMA, DriveDescriptionError, load_drive
from scenarios.maps.flux_map import linear_flux_map, write_flux_map

from conftest import patient

#: TOML texts of hostile values
HOSTILE = {
    "400 digits": "9" * 400,
    "-400 digits": "-" + "9" * 400,
    "1e308": "1e308",
    "-1e308": "-1e308",
    "5e-324": "5e-324",
    "nan": "nan",
    "inf": "inf",
    "-inf": "-inf",
    "-1": "-1",
    "0": "0",
    "0.0": "0.0",
    "2**63": str(2**63),
    "NUL": '"\\u0000"',
    "unknown user": '"~nosuchuser_h4/x"',
    "huge string": '"' + "x" * 100_000 + '"',
    "empty string": '""',
    "true": "true",
    "date": "1979-05-27",
    "array": "[1, 2]",
    "nested array": "[[[[[1]]]]]",
    "table": "{ a = 1 }",
    "nested table": "{ a = { b = { c = 1 } } }",
    "array of huge strings": '["' + "y" * 10_000 + '"]',
}
#: the default run: values that cover every path of Rule.check
SAMPLE = ("400 digits", "1e308", "5e-324", "nan", "-1", "0", "NUL", "unknown user", "huge string", "table")


@pytest.fixture(scope="module")
def small_map(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("fuzz") / "m.csv"
    write_flux_map(p, linear_flux_map(2e-4, 5e-4, 0.07, 300.0, n=9))
    return p


def _file(folder: Path, small_map: Path, path: str, value: str) -> Path:
    section, _, name = path.rpartition(".")
    motor = f'flux_map = "{small_map}"\n' if path != "motor.flux_map" else f"flux_map = {value}\n"
    text = ""
    if not section:
        text += f"{name} = {value}\n"
    text += "[motor]\n" + motor
    if section == "motor" and name != "flux_map":
        text += f"{name} = {value}\n"
    elif section and section != "motor":
        text += f"[{section}]\n{name} = {value}\n"
        if section == "fault" and name not in FAULT_TRIGGERS:   # the one trigger every [fault] needs
            text += "t_s = 1.0\n"
    p = folder / "fuzz.toml"
    p.write_text(text)
    return p


def _fuzz(tmp_path: Path, small_map: Path, values) -> int:
    loaded = 0
    for key in SCHEMA:
        for v in values:
            p = _file(tmp_path, small_map, key.path, HOSTILE[v])
            try:
                load_drive(p)
                loaded += 1
            except DriveDescriptionError as e:
                assert Path(e.file) == p, (key.path, v, e)
                assert e.key.startswith(key.path) or e.key in ("(syntax)", "line 1", "line 2", "line 3", "line 4"), \
                    (key.path, v, e.key)
                assert str(e).isprintable() and len(str(e)) < 3000, (key.path, v, str(e)[:200])
            # any other exception fails the test with its traceback: what the fuzz hunts
    return loaded


def test_the_loader_refuses_every_hostile_value_by_key(tmp_path, small_map):
    t0 = time.perf_counter()
    _fuzz(tmp_path, small_map, SAMPLE)
    assert time.perf_counter() - t0 < patient(120)


@pytest.mark.slow
def test_the_loader_refuses_every_hostile_value_by_key_all(tmp_path, small_map):
    _fuzz(tmp_path, small_map, HOSTILE)


def test_a_value_the_fmu_refuses_is_refused_at_load(tmp_path, small_map):
    """The ranges are the FMUs' own (their modelDescription min/max): at each bound and beyond."""
    from scenarios.core.fmu_ranges import fmu_ranges
    from scenarios.drives.description import FMU_PARAMETER
    r = fmu_ranges()
    tried = 0
    for key in SCHEMA:
        fmu = FMU_PARAMETER.get(key.path)
        if fmu is None or r[fmu].hi is None:
            continue
        hi = r[fmu].hi
        beyond = hi * 1.5 + 1 if key.rule.kind == "real" else int(hi) + 1
        with pytest.raises(DriveDescriptionError) as e:
            load_drive(_file(tmp_path, small_map, key.path, repr(beyond)))
        assert e.value.key == key.path
        tried += 1
    assert tried >= 10


# -- IpmsmDrive: a bounded communication step ----------------------------------------------------
_CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import fmi2_raw as raw
u = raw.Unzipped(sys.argv[2], sys.argv[3])
inst = raw.Instance(u, "big_step", logging_on=True)
inst.init()
inputs = dict(T_ref=50.0, w_m=300.0, u_dc=355.0, T_magnet=293.15, T_winding=293.15)
inst.set(**inputs)
out = {}
for h in (1e6, 1e12, 1e300, float("inf")):
    t0 = time.perf_counter()
    out[repr(h)] = (inst.step(h=h), time.perf_counter() - t0)
out["log"] = inst.log.text()[-2000:]
inst.set(**inputs)
out["after"] = inst.step(h=0.01)
out["at_limit"] = inst.step(h=10.0)
out["T_e"] = inst.get("T_e")
print(json.dumps(out))
"""


def test_ipmsm_drive_refuses_a_step_beyond_its_bound_and_stays_usable(tmp_path):
    from conftest import fmu_path
    fmu = fmu_path("IpmsmDrive")
    r = subprocess.run([sys.executable, "-c", _CHILD, str(Path(__file__).parent), str(fmu), str(tmp_path)],
                       capture_output=True, text=True, timeout=patient(120))
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.splitlines()[-1])
    for h in ("1000000.0", "1000000000000.0", "1e+300", "inf"):
        status, wall = out[h]
        assert status == 3 and wall < patient(5.0), (h, status, wall)   # fmi2Error at once (a step taken: hours)
    assert "sample times" in out["log"] or "communication step" in out["log"]
    assert out["after"] == 0 and out["at_limit"] == 0 and math.isfinite(out["T_e"])
