"""The CI gate (scenarios/runs/check.py) under hostile names and failing runs (issue 24): results
keyed by the cycle's identity, one test case per cycle x limit whatever the names, a cycle that
could not run an <error> and never a pass, JUnit that xml.etree parses, outputs 0644 and atomic.
The runs are replaced by canned summaries (the gate's logic is under test; test_check.py runs
real cycles), chosen by the cycle's samples so that two files of one name differ."""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import pytest

from scenarios import __main__ as cli
from scenarios.maps.flux_map import DEFAULT_MAP
from scenarios.runs.check import CYCLE_FOLLOWING

LIMITS = {"Wh_per_km_max": 200.0, "soc_end_min": 0.5}
#: the verdicts of one cycle: the drive's limits and every check's cycle-following ones
VERDICTS = {**LIMITS, **CYCLE_FOLLOWING}


@dataclass
class FakeSummary:
    d: dict
    wall_s: float = 0.5

    def to_dict(self) -> dict:
        return self.d


@pytest.fixture
def fake_runs(monkeypatch):
    """simulate() replaced: a cycle whose top speed is 20 m/s uses 300 Wh/km (fails Wh_per_km_max),
    5 m/s 100 Wh/km (passes), 7 m/s raises (an FMU that refused), 0 m/s stands (Wh_per_km None)."""
    calls = []

    def simulate(cycle, spec, fmus=None, out=None, progress=True):
        top = float(max(cycle.speed_mps))
        calls.append(top)
        if top == 7.0:
            raise RuntimeError("fmi2DoStep failed: the FMU refused\x1b[31m")
        wh = {20.0: 300.0, 5.0: 100.0, 0.0: None}[top]
        km = 5.0 * top / 1000.0  # the car followed the cycle: its distance, no speed error
        return FakeSummary({"Wh_per_km": wh, "soc_end": 0.9, "speed_rmse_mps": 0.0, "distance_km": km,
                            "cycle_distance_km": km, "cycle_moving_s": 10.0})

    import scenarios.runs.simulate as sim
    monkeypatch.setattr(sim, "simulate", simulate)
    return calls


def cycle(folder: Path, name: str, top: float) -> str:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / name
    p.write_text(f"time_s,speed_mps\n0,0\n5,{top}\n10,0\n")
    return str(p)


def toml_str(s: str) -> str:
    """`s` as a TOML basic string: every character TOML would not take raw as \\uXXXX."""
    return '"' + "".join(c if c.isprintable() and c not in '"\\' else f"\\u{ord(c):04x}" for c in s) + '"'


def drive(tmp_path: Path, cycles: list[str], name: str = "gate") -> Path:
    text = (f'name = {toml_str(name)}\n[motor]\nflux_map = "{DEFAULT_MAP}"\n[checks]\n'
            + "cycles = [" + ", ".join(toml_str(c) for c in cycles) + "]\n"
            + "".join(f"{k} = {v!r}\n" for k, v in LIMITS.items()))
    p = tmp_path / "drive.toml"
    p.write_text(text)
    return p


def run(tmp_path: Path, path: Path, capsys, junit: Path | None = None):
    junit = junit or tmp_path / "reports" / "j.xml"
    status = cli.main(["check", str(path), "--out", str(tmp_path / "out"), "--junit", str(junit)])
    io = capsys.readouterr()
    return status, junit, io


def cases_of(junit: Path) -> list[tuple[str, str, str]]:
    """(classname, name, outcome) of every test case, the file parsed by xml.etree."""
    root = ET.parse(junit).getroot()
    out = []
    for c in root.iter("testcase"):
        outcome = "error" if c.find("error") is not None else "failure" if c.find("failure") is not None else "pass"
        out.append((c.get("classname"), c.get("name"), outcome))
    return out


def test_two_cycles_of_one_name_are_two_cycles(tmp_path, capsys, fake_runs):
    a = cycle(tmp_path / "a", "x.csv", 20.0)   # fails Wh_per_km_max
    b = cycle(tmp_path / "b", "x.csv", 5.0)    # passes
    status, junit, io = run(tmp_path, drive(tmp_path, [a, b]), capsys)
    assert status == 1, io.err
    cases = cases_of(junit)
    assert len(cases) == 2 * len(VERDICTS) and len(set(cases)) == len(cases)
    assert ("gate/a/x.csv", "Wh_per_km_max", "failure") in cases
    assert ("gate/b/x.csv", "Wh_per_km_max", "pass") in cases
    assert "FAIL gate/a/x.csv Wh_per_km" in io.out and "FAIL" in (tmp_path / "out" / "check.md").read_text()


def test_the_same_cycle_listed_twice_runs_once(tmp_path, capsys, fake_runs):
    a = cycle(tmp_path, "x.csv", 5.0)
    status, junit, io = run(tmp_path, drive(tmp_path, [a, a]), capsys)
    assert status == 0 and len(cases_of(junit)) == len(VERDICTS) and fake_runs == [5.0]


def test_a_cycle_that_cannot_run_is_an_error_not_a_pass(tmp_path, capsys, fake_runs):
    good = cycle(tmp_path, "good.csv", 5.0)
    bad = cycle(tmp_path, "bad.csv", 7.0)
    status, junit, io = run(tmp_path, drive(tmp_path, [good, bad]), capsys)
    assert status == 2, io.err
    cases = cases_of(junit)
    assert {(n, o) for c, n, o in cases if c == "gate/bad.csv"} == {(k, "error") for k in VERDICTS}
    assert {o for c, n, o in cases if c == "gate/good.csv"} == {"pass"}
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite.get("errors") == str(len(VERDICTS)) and suite.get("tests") == str(2 * len(VERDICTS))
    assert "\x1b" not in io.out + io.err and "ERROR" in (tmp_path / "out" / "check.md").read_text()


def test_a_standing_car_fails_a_per_km_limit_with_no_figure(tmp_path, capsys, fake_runs):
    s = cycle(tmp_path, "stand.csv", 0.0)
    status, junit, io = run(tmp_path, drive(tmp_path, [s]), capsys)
    assert status == 1
    assert ("gate/stand.csv", "Wh_per_km_max", "failure") in cases_of(junit)


@pytest.mark.parametrize("bad", ["\x01", "\x1b[2J", "\ufffe", "\x7f", "&<>\"'", "\u2028"])
def test_names_with_any_character_give_well_formed_junit(tmp_path, capsys, fake_runs, bad):
    c = cycle(tmp_path, f"c{bad.replace('/', '_')}.csv", 5.0)
    path = drive(tmp_path, [c], name=f"drive{bad}")
    status, junit, io = run(tmp_path, path, capsys)
    assert status == 0, io.err
    root = ET.parse(junit).getroot()   # well-formed XML 1.0
    assert len(list(root.iter("testcase"))) == len(VERDICTS)
    assert all(ch.isprintable() or ch in "\n" for ch in io.out), repr(io.out)


def test_outputs_are_0644_atomic_and_a_junit_symlink_stays_a_link(tmp_path, capsys, fake_runs):
    c = cycle(tmp_path, "x.csv", 5.0)
    target = tmp_path / "ci" / "real.xml"
    target.parent.mkdir()
    link = tmp_path / "link.xml"
    link.symlink_to(target)
    old = os.umask(0o077)
    try:
        status, junit, io = run(tmp_path, drive(tmp_path, [c]), capsys, junit=link)
    finally:
        os.umask(old)
    assert status == 0, io.err
    assert link.is_symlink() and target.is_file() and cases_of(target)
    for p in (target, tmp_path / "out" / "check.md"):
        assert p.stat().st_mode & 0o777 == 0o644, oct(p.stat().st_mode)
    assert not [p for p in (tmp_path / "out").iterdir() if p.name.startswith(".")]


def test_an_unwritable_junit_folder_is_refused_before_any_run(tmp_path, capsys, fake_runs, unwritable_folder):
    c = cycle(tmp_path, "x.csv", 5.0)
    ro = unwritable_folder
    status, junit, io = run(tmp_path, drive(tmp_path, [c]), capsys, junit=ro / "j.xml")
    assert status == 2 and "--junit" in io.err and str(ro) in io.err
    assert fake_runs == [] and not (tmp_path / "out" / "check.md").exists()


def test_a_junit_path_that_is_a_folder_is_refused_before_any_run(tmp_path, capsys, fake_runs):
    c = cycle(tmp_path, "x.csv", 5.0)
    d = tmp_path / "j.xml"
    d.mkdir()
    status, junit, io = run(tmp_path, drive(tmp_path, [c]), capsys, junit=d)
    assert status == 2 and "--junit" in io.err and fake_runs == []


def test_xml_text_replaces_everything_xml_forbids():
    from scenarios.runs.check import xml_text
    forbidden = [chr(c) for c in (*range(0x00, 0x09), 0x0b, 0x0c, *range(0x0e, 0x20), 0xfffe, 0xffff)]
    forbidden.append("\udcff")  # a surrogate: an undecodable byte of a file name
    for ch in forbidden:
        s = xml_text(f"a{ch}b")
        assert ch not in s and s.startswith("a\\u") and s.endswith("b")
        ET.fromstring(f"<x a='{s}'>{s}</x>")
    assert xml_text("a\tb\nc") == "a\tb\nc"


def test_a_non_utf8_folder_and_drive_path_give_a_report(tmp_path, capsys, fake_runs):
    """A folder whose name is not UTF-8 (bytes 0xff): check.md and the JUnit are written, the
    names escaped, nothing raised after the runs."""
    odd = tmp_path / os.fsdecode(b"caf\xff")
    odd.mkdir()
    cycle(odd, "x.csv", 5.0)
    path = drive(odd, ["x.csv"])   # relative: a TOML file holds UTF-8 only
    status, junit, io = run(odd, path, capsys, junit=odd / "j.xml")
    assert status == 0, io.err
    assert cases_of(junit) and "\\udcff" in (odd / "out" / "check.md").read_text()
