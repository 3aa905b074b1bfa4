"""`python -m scenarios check` (scenarios/runs/check.py, docs/ci.md): a passing and a failing drive,
the exit codes 0 / 1 / 2, check.md and the JUnit XML parsed back, nothing written on bad input."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from scenarios import __main__ as cli
from scenarios.maps.flux_map import DEFAULT_MAP
from scenarios.runs.check import CYCLE_FOLLOWING, judge

#: two short user cycles (CSV, relative to the drive file): a start, cruise and stop of 30 s, and
#: a faster one of 20 s that ends at speed
CYCLES = {
    "town.csv": [(0, 0.0), (2, 0.0), (10, 11.0), (20, 11.0), (28, 0.0), (30, 0.0)],
    "road.csv": [(0, 15.0), (8, 22.0), (20, 22.0)],
}


def write_case(tmp_path: Path, limits: dict, cycles=("town.csv", "road.csv"), name="gate") -> Path:
    for file, rows in CYCLES.items():
        (tmp_path / file).write_text("time_s,speed_mps\n" + "".join(f"{t},{v}\n" for t, v in rows))
    text = f'name = "{name}"\n[motor]\nflux_map = "{DEFAULT_MAP}"\n[checks]\n'
    text += "cycles = [" + ", ".join(f'"{c}"' for c in cycles) + "]\n"
    text += "".join(f"{k} = {v!r}\n" for k, v in limits.items())
    path = tmp_path / "drive.toml"
    path.write_text(text)
    return path


def run_check(path: Path, tmp_path: Path, capsys) -> tuple[int, Path, Path, str]:
    out, junit = tmp_path / "out", tmp_path / "reports" / "report.xml"
    status = cli.main(["check", str(path), "--out", str(out), "--junit", str(junit), "--backend", "drive"])
    return status, out, junit, capsys.readouterr()


PASSING = {"Wh_per_km_max": 400.0, "speed_rmse_mps_max": 0.5, "torque_rmse_Nm_max": 5.0,
           "torque_error_max_Nm_max": 80.0, "soc_end_min": 0.4}


def test_passing_drive_exits_0_with_a_clean_report(tmp_path, capsys):
    status, out, junit, io = run_check(write_case(tmp_path, PASSING), tmp_path, capsys)
    assert status == 0, io.err
    root = ET.parse(junit).getroot()
    suites = root.findall("testsuite")
    assert [s.get("name") for s in suites] == ["gate"]
    cases = suites[0].findall("testcase")
    assert len(cases) == 2 * (len(PASSING) + len(CYCLE_FOLLOWING)) and suites[0].get("tests") == str(len(cases))
    assert suites[0].get("failures") == "0" and not list(root.iter("failure"))
    assert {c.get("classname") for c in cases} == {"gate/town.csv", "gate/road.csv"}
    assert {c.get("name") for c in cases} == set(PASSING) | set(CYCLE_FOLLOWING)
    md = (out / "check.md").read_text()
    assert "PASS" in md and md.count("| pass |") == len(cases)
    assert not list(junit.parent.glob(".*")) and not list(out.glob(".*"))   # no temporary files left


def test_failing_limit_exits_1_and_names_figure_and_limit(tmp_path, capsys):
    limits = {**PASSING, "Wh_per_km_max": 1.0}
    status, out, junit, io = run_check(write_case(tmp_path, limits), tmp_path, capsys)
    assert status == 1
    suite = ET.parse(junit).getroot().find("testsuite")
    failures = [(c.get("classname"), c.get("name"), c.find("failure")) for c in suite.findall("testcase")
                if c.find("failure") is not None]
    assert [(cls, name) for cls, name, _ in failures] == [("gate/town.csv", "Wh_per_km_max"),
                                                          ("gate/road.csv", "Wh_per_km_max")]
    assert suite.get("failures") == "2" and suite.get("tests") == str(2 * (len(limits) + len(CYCLE_FOLLOWING)))
    for _, _, f in failures:
        msg = f.get("message")
        figure = float(msg.split("Wh_per_km = ")[1].split(",")[0])
        assert figure > 1.0 and "limit <= 1" in msg and "FAILED" in msg
    assert "FAIL" in (out / "check.md").read_text()
    assert "FAIL gate/town.csv Wh_per_km = " in io.out


@pytest.mark.parametrize("case", ["no limits", "no cycles", "malformed cycle", "unknown cycle"])
def test_bad_input_exits_2_and_writes_nothing(case, tmp_path, capsys):
    if case == "no limits":
        path = write_case(tmp_path, {})
    elif case == "no cycles":
        path = write_case(tmp_path, PASSING, cycles=())
        path.write_text(path.read_text().replace("cycles = []\n", ""))
    elif case == "malformed cycle":
        path = write_case(tmp_path, PASSING, cycles=("town.csv",))
        (tmp_path / "town.csv").write_text("time_s,speed_mps\n0,0\n1,-5\n")
    else:
        path = write_case(tmp_path, PASSING, cycles=("UDDS", "FTP-99"))
    status, out, junit, io = run_check(path, tmp_path, capsys)
    assert status == 2
    assert str(path) in io.err and "checks" in io.err
    assert not out.exists() and not junit.parent.exists()


def test_judge_directions_and_nan():
    s = {"Wh_per_km": 120.0, "soc_end": 0.45, "speed_rmse_mps": math.nan}
    v = judge("c", s, {"Wh_per_km_max": 130.0, "soc_end_min": 0.5, "speed_rmse_mps_max": 1.0})
    assert [x.passed for x in v] == [True, False, False, False, False]   # a NaN figure never passes
    assert [x.limit for x in v[3:]] == list(CYCLE_FOLLOWING)  # every check's: no cycle figures, no pass
