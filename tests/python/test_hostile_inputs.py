"""The Python surfaces under hostile input (issue 24, docs/inputs.md): drive descriptions, cycles,
command-line numbers, study specifications, map files, output folders. Every input is generated
here; every command runs in a child process with an address-space limit and a timeout, and must
end in exit 2 with one line naming the file and the key (or line) and what was expected: no
traceback, no hang, no exhausted machine, nothing written."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from scenarios.core.paths import ROOT
from scenarios.maps.flux_map import DEFAULT_MAP

from conftest import address_space_limit, patient

#: bytes of address space a refusing command may map: the interpreter with numpy, scipy and the
#: package imported is about 0.6 GiB; the bombs of the issue asked for 2.5 GB to 745 GiB
CHILD_AS_BYTES = 3 << 29   # 1.5 GiB
CHILD_TIMEOUT_S = patient(60.0)


def cli(*argv: str, timeout: float = CHILD_TIMEOUT_S, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    """python -m scenarios ARGV in a child with the address-space limit; its run time in .wall."""
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "scenarios", *argv], cwd=cwd, capture_output=True, timeout=timeout,
                       preexec_fn=address_space_limit(CHILD_AS_BYTES))
    r.wall = time.perf_counter() - t0
    r.err = r.stderr.decode("utf-8", "strict")
    return r


def assert_refused(r, file, key: str, *words: str) -> None:
    """Exit 2, one line on stderr naming `file` and `key`, no traceback."""
    assert r.returncode == 2, (r.returncode, r.err[-3000:])
    assert "Traceback" not in r.err, r.err[-3000:]
    lines = [x for x in r.err.splitlines() if x.strip()]
    assert len(lines) == 1, r.err
    assert str(file) in lines[0] and key in lines[0], lines[0]
    for w in words:
        assert w in lines[0], lines[0]
    assert lines[0].isprintable()


# -- drive descriptions ---------------------------------------------------------------------------
def drive(tmp_path: Path, body: str, name: str = "bad.toml", flux_map: str | None = None) -> Path:
    fm = str(DEFAULT_MAP) if flux_map is None else flux_map
    p = tmp_path / name
    p.write_bytes(f'[motor]\nflux_map = "{fm}"\n{body}'.encode("utf-8", "surrogateescape"))
    return p


DRIVE_CASES = {
    # name: (TOML after [motor] flux_map, key named, words of the expectation)
    "400-digit integer": ("[vehicle]\nmass = " + "9" * 400 + "\n", "vehicle.mass", "a number"),
    "R_s beyond the plant's range": ("R_s = 1e308\n", "motor.R_s", "(0, 1000]"),
    "I_max 1e308": ("I_max = 1e308\n", "motor.I_max", "100000"),
    "R0 zero": ("[battery]\nR0 = 0.0\n", "battery.R0", "(0, 100]"),
    "wheel radius denormal": ("[vehicle]\nwheel_radius = 5e-324\n", "vehicle.wheel_radius", "[0.01, 10]"),
    "gear ratio 1e308": ("[vehicle]\ngear_ratio = 1e308\n", "vehicle.gear_ratio", "[0.1, 100]"),
    "tau1 1e308": ("[battery]\ntau1 = 1e308\n", "battery.tau1", "100000"),
    "inverter 1e308": ("[inverter]\nE_on = 1e308\n", "inverter.E_on", "[0, 100]"),
    "nan": ("[vehicle]\nmass = nan\n", "vehicle.mass", "a number"),
    "inf": ("[vehicle]\nmass = inf\n", "vehicle.mass", "a number"),
    "fault time 400 digits": ("[fault]\nt_s = " + "9" * 400 + "\n", "fault.t_s", "a number"),
    "fault speed inf": ("[fault]\nv_kmh = inf\n", "fault.v_kmh", "a number"),
    "fault state NUL": ('[fault]\nt_s = 1.0\nsafe_state = "asc\\u0000"\n', "fault.safe_state", "'asc'"),
    "fault two triggers": ("[fault]\nt_s = 1.0\nspeed_rpm = 1e308\n", "fault.speed_rpm", "exactly one trigger"),
    "fault duration 1e308": ("[fault]\nt_s = 1.0\nduration_s = 1e308\n", "fault.duration_s", "1e+07"),
    "fault i_d_demag -1e308": ("[fault]\nt_s = 1.0\ni_d_demag = -1e308\n", "fault.i_d_demag", "-100000"),
    "fault nested table": ("[fault]\nt_s = { a = { b = 1 } }\n", "fault.t_s", "a number"),
    "fault limit without a fault": ('[checks]\ncycles = ["UDDS"]\nfault_charge_Ah_max = 1.0\n',
                                    "checks.fault_charge_Ah_max", "[fault] table"),
    "negative OCV": (None, "battery.ocv", "OCV"),
    "short OCV row": (None, "battery.ocv", "OCV"),
}


@pytest.mark.parametrize("case", list(DRIVE_CASES))
def test_a_drive_value_the_models_cannot_carry_is_refused_at_load(case, tmp_path):
    body, key, words = DRIVE_CASES[case]
    if body is None:  # an OCV curve of the given fault
        ocv = tmp_path / "ocv.csv"
        rows = {"negative OCV": "soc,ocv_cell_V\n0.0,-3.0\n0.5,-3.5\n1.0,-4.0\n",
                "short OCV row": "soc,ocv_cell_V\n0.0,3.0\n0.5\n1.0,4.1\n"}[case]
        ocv.write_text(rows)
        body = f'[battery]\nocv = "{ocv}"\n'
    p = drive(tmp_path, body)
    r = cli("run", "UDDS", "--drive", str(p), "--out", str(tmp_path / "out"))
    assert_refused(r, p, key)
    assert words in r.err or case in ("negative OCV", "short OCV row")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("case", ["nul", "unknown user", "symlink loop", "a folder", "over 512 points",
                                  "sparse 2 GB", "non-UTF-8 bytes", "a named pipe"])
def test_a_hostile_flux_map_path_or_file_is_refused(case, tmp_path):
    fm = {"nul": "\\u0000x.csv", "unknown user": "~nosuchuser_h4/x.csv"}.get(case)
    if case == "symlink loop":
        (tmp_path / "a.csv").symlink_to(tmp_path / "b.csv")
        (tmp_path / "b.csv").symlink_to(tmp_path / "a.csv")
        fm = str(tmp_path / "a.csv")
    elif case == "a folder":
        (tmp_path / "d.csv").mkdir()
        fm = str(tmp_path / "d.csv")
    elif case == "over 512 points":
        m = tmp_path / "big.csv"
        m.write_text("i_d,i_q,psi_d,psi_q\n" + "".join(f"{-d},{q},{0.07 - 1e-4 * d},{1e-4 * q}\n"
                                                         for d in range(513) for q in range(3)))
        fm = str(m)
    elif case == "sparse 2 GB":
        m = tmp_path / "sparse.csv"
        with open(m, "wb") as f:
            f.truncate(2 << 30)
        fm = str(m)
    elif case == "non-UTF-8 bytes":
        m = tmp_path / "latin.csv"
        m.write_bytes(b"# \xe9t\xe9\ni_d,i_q,psi_d,psi_q\n0,0,0.07,0\n")
        fm = str(m)
    elif case == "a named pipe":
        m = tmp_path / "fifo.csv"
        os.mkfifo(m)
        fm = str(m)
    p = drive(tmp_path, "", flux_map=fm)
    r = cli("run", "UDDS", "--drive", str(p), "--out", str(tmp_path / "out"), timeout=patient(30))
    assert_refused(r, p, "motor.flux_map")
    if case in ("sparse 2 GB", "over 512 points"):  # refused for its size, not by the memory limit running out
        assert "at most" in r.err and "MemoryError" not in r.err, r.err
    assert r.wall < patient(20.0)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("case", ["dotted key of 40 kB", "nesting 1e5 deep", "non-UTF-8", "a folder", "1 GB file"])
def test_a_hostile_toml_is_refused_before_it_is_parsed(case, tmp_path):
    p = tmp_path / "bad.toml"
    if case == "dotted key of 40 kB":
        p.write_text("a" + ".a" * 20_000 + " = 1\n")
    elif case == "nesting 1e5 deep":
        p.write_text("x = " + "[" * 100_000 + "]" * 100_000 + "\n")
    elif case == "non-UTF-8":
        p.write_bytes(b'name = "caf\xe9"\n')
    elif case == "a folder":
        p.mkdir()
    else:
        with open(p, "wb") as f:
            f.truncate(1 << 30)
    r = cli("run", "UDDS", "--drive", str(p), "--out", str(tmp_path / "out"), timeout=patient(30))
    assert_refused(r, p, "(file)" if case in ("a folder", "1 GB file") else "line 1")
    assert r.wall < patient(20.0)


# -- cycles -----------------------------------------------------------------------------------------
CYCLE_CASES = {
    "NaN": (b"time_s,speed_mps\n0,0\n1,nan\n2,0\n", "line 3"),
    "empty": (b"", "(file)"),
    "header only": (b"time_s,speed_mps\n", "(file)"),
    "non-monotone": (b"time_s,speed_mps\n0,0\n2,1\n1,0\n", "line 4"),
    "non-UTF-8": (b"time_s,speed_mps\n0,0\n1,1\xff\n", "line 3"),
    "too short": (b"time_s,speed_mps\n0,0\n0.005,0\n", "(file)"),
    "too long": (b"time_s,speed_mps\n0,0\n1e9,0\n", "line 3"),
    "in km/h": (b"time_s,speed_mps\n0,0\n1,130\n", "line 3"),
    "a line of 1 MB": (b"time_s,speed_mps\n0," + b"1" * (1 << 20) + b"\n", "line 2"),
}


@pytest.mark.parametrize("case", list(CYCLE_CASES))
def test_a_hostile_cycle_is_refused_with_its_line(case, tmp_path):
    data, where = CYCLE_CASES[case]
    c = tmp_path / "c.csv"
    c.write_bytes(data)
    r = cli("run", str(c), "--out", str(tmp_path / "out"), timeout=patient(30))
    assert_refused(r, c, where)
    assert not (tmp_path / "out").exists()


def test_a_cycle_file_that_is_a_pipe_does_not_block(tmp_path):
    c = tmp_path / "c.csv"
    os.mkfifo(c)
    r = cli("run", str(c), "--out", str(tmp_path / "out"), timeout=patient(30))
    assert_refused(r, c, "(file)", "regular file")


def test_a_week_long_cycle_samples_lazily():
    """Bounded memory for a long cycle: the samples are made a block at a time."""
    import numpy as np

    from scenarios.vehicle.cycles import Cycle, sampled
    c = Cycle("long", np.array([0.0, 600_000.0]), np.array([0.0, 10.0]))
    t, v = sampled(c, 0.01, 60_000_000)
    assert len(t) == 60_000_001 and t[0] == 0.0 and t[60_000_000] == pytest.approx(600_000.0)
    assert v[30_000_000] == pytest.approx(5.0)
    ref = c.time_s[0] + 0.01 * np.arange(200_000)
    assert [t[k] for k in range(0, 200_000, 997)] == ref[::997].tolist()  # the values the loop always had


# -- command-line numbers and paths -------------------------------------------------------------------
@pytest.mark.parametrize("argv,key", [
    (["run", "UDDS", "--u-dc-scale", "nan"], "--u-dc-scale"),
    (["run", "UDDS", "--u-dc-scale", "-1"], "--u-dc-scale"),
    (["run", "UDDS", "--u-dc-scale", "0"], "--u-dc-scale"),
    (["run", "UDDS", "--u-dc-scale", "inf"], "--u-dc-scale"),
    (["run", "UDDS", "--magnet-degC", "1e308"], "--magnet-degC"),
    (["sweep", "--u-dc", "nan"], "--u-dc"),
    (["sweep", "--u-dc", "1e308"], "--u-dc"),
    (["map", "show", str(DEFAULT_MAP), "--u-dc", "1e308"], "--u-dc"),
    (["map", "show", str(DEFAULT_MAP), "--I-max", "nan"], "--I-max"),
    (["map", "show", str(DEFAULT_MAP), "--I-max", "-1"], "--I-max"),
    (["compare", "--cycles", "UDDS", "nosuch.csv"], "--cycles"),
    (["run", "nosuch.csv"], "cycle"),
    (["study", "x.toml", "--scheduler", "garbage"], "--scheduler"),
    (["study", "x.toml", "--scheduler", "inproc://x"], "--scheduler"),
])
def test_a_bad_command_line_number_is_refused(argv, key, tmp_path):
    r = cli(*argv, "--out", str(tmp_path / "out"))
    assert_refused(r, "(command line)", key)
    assert not (tmp_path / "out").exists()


def test_an_unwritable_out_is_refused_before_any_run(unwritable_folder):
    ro = unwritable_folder
    r = cli("run", "UDDS", "--out", str(ro / "x"))
    assert_refused(r, ro / "x", "--out")


def test_a_drive_name_cannot_lead_the_run_outside_out():
    from scenarios.__main__ import _slug
    from scenarios.core.boundary import InputError, inside
    s = _slug("UDDS_x/../../../pwn/evil_ferrari")
    assert s == "UDDS_x_pwn_evil_ferrari"
    assert inside(ROOT / "out", s, "run").parent == (ROOT / "out").resolve()
    for bad in ("../x", "/etc", "a/../../b", "\0"):
        with pytest.raises(InputError):
            inside(ROOT / "out", bad, "run")


def test_run_without_out_stays_in_out_with_a_hostile_drive_name(tmp_path):
    """A drive named x/../../../pwn/evil: summary.json, trace.csv, run.png under ROOT/out only."""
    c = tmp_path / "short.csv"
    c.write_text("time_s,speed_mps\n0,0\n1,1\n2,0\n")
    p = tmp_path / "evil.toml"
    p.write_text(f'name = "x/../../../pwn_h4/evil"\n[motor]\nflux_map = "{DEFAULT_MAP}"\n')
    r = subprocess.run([sys.executable, "-m", "scenarios", "run", str(c), "--drive", str(p)], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    out = ROOT / "out" / "short_x_pwn_h4_evil_ferrari"
    try:
        assert (out / "summary.json").is_file() and (out / "trace.csv").is_file()
        assert oct((out / "summary.json").stat().st_mode & 0o777) == "0o644"
        assert not (ROOT.parent / "pwn_h4").exists() and not (ROOT.parents[1] / "pwn_h4").exists()
        import json
        json.loads((out / "summary.json").read_text(),
                   parse_constant=lambda c: pytest.fail(f"{c} in summary.json"))
    finally:
        import shutil
        shutil.rmtree(out, ignore_errors=True)


# -- study specifications -----------------------------------------------------------------------------
@pytest.mark.parametrize("case", ["1e9 runs", "non-UTF-8", "a folder", "deeply nested", "huge number"])
def test_a_hostile_study_spec_is_refused_in_bounded_memory(case, tmp_path):
    p = tmp_path / "s.toml"
    if case == "1e9 runs":
        p.write_text("[study]\nu_dc_scale = [" + ",\n".join(f"{0.5 + i * 1e-3:.4f}" for i in range(1000)) + "]\n"
                     "T_magnet_degC = [" + ",\n".join(f"{i * 0.1:.1f}" for i in range(1000)) + "]\n"
                     "T_winding_degC = [" + ",\n".join(f"{i * 0.1:.1f}" for i in range(1000)) + "]\n")
        key = "study.T_magnet_degC"
    elif case == "non-UTF-8":
        p.write_bytes(b'[study]\ncycles = ["caf\xe9"]\n')
        key = "line 2"
    elif case == "a folder":
        p.mkdir()
        key = "(file)"
    elif case == "deeply nested":
        p.write_text("[study]\nlut_grids = " + "[" * 5000 + "]" * 5000 + "\n")
        key = "line 2"
    else:
        p.write_text("[study]\nu_dc_scale = " + "9" * 400 + "\n")
        key = "study.u_dc_scale"
    r = cli("study", str(p), "--out", str(tmp_path / "out"), timeout=patient(30))
    assert r.returncode == 2, r.err
    assert "Traceback" not in r.err and str(p) in r.err and key in r.err, r.err
    assert r.wall < patient(20.0)


def test_twenty_thousand_runs_are_planned_in_linear_time(tmp_path):
    from scenarios.study.spec import parse
    study = {"u_dc_scale": [0.5 + i * 1e-3 for i in range(200)], "T_magnet_degC": [float(i) for i in range(100)]}
    t0 = time.perf_counter()
    spec = parse({"study": study}, tmp_path / "s.toml")
    wall = time.perf_counter() - t0
    assert len(spec.runs) == 20_000 and wall < patient(10.0), wall
    from scenarios.study.spec import SpecError
    runs = [{"u_dc_scale": 0.5 + i * 1e-5} for i in range(20_000)] + [{"u_dc_scale": 0.5 + 19_999e-5}]
    t0 = time.perf_counter()
    with pytest.raises(SpecError, match="the same run twice"):   # the duplicate last: the worst case
        parse({"run": runs}, tmp_path / "s.toml")
    assert time.perf_counter() - t0 < patient(10.0)


# -- map show / import (bounded) ------------------------------------------------------------------------
def test_a_mat_file_that_inflates_beyond_the_limit_is_refused_unread(tmp_path):
    import numpy as np
    import scipy.io as sio
    m = tmp_path / "bomb.mat"
    a = np.zeros((3000, 3000))   # 72 MB of doubles, 0.3 MB compressed
    sio.savemat(m, {"Id": a, "Iq": a[:1], "Fd": a[:1], "Fq": a[:1]}, do_compression=True)
    r = cli("map", "import", str(m), "--out", str(tmp_path / "x.csv"), timeout=patient(30))
    assert r.returncode == 2 and str(m) in r.err and "inflated" in r.err, r.err
    assert not (tmp_path / "x.csv").exists()


def test_a_run_in_which_the_car_stands_writes_strict_json(controller_fmu, plant_fmu, tmp_path):
    """UDDS's first 5 s: no distance, Wh_per_km undefined: null in summary.json (listed in
    `undefined`), never NaN; the file 0644."""
    import json

    from scenarios.runs.simulate import RunSpec, simulate
    from scenarios.vehicle.cycles import load_cycle, segment
    simulate(segment(load_cycle("UDDS"), 0.0, 5.0), RunSpec(), fmus=(controller_fmu, plant_fmu), out=tmp_path,
             progress=False)
    text = (tmp_path / "summary.json").read_text()
    d = json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in summary.json"))
    assert d["Wh_per_km"] is None and "Wh_per_km" in d["undefined"]
    assert (tmp_path / "summary.json").stat().st_mode & 0o777 == 0o644


@pytest.mark.parametrize("cmd", ["run", "check", "study"])
def test_an_out_that_cannot_be_a_folder_is_refused_before_any_run(cmd, tmp_path):
    """--out below a regular file (the one unwritable folder even root meets)."""
    f = tmp_path / "file"
    f.write_text("x")
    out = f / "out"
    spec = tmp_path / "s.toml"
    spec.write_text('[study]\ncycles = ["UDDS"]\nwindow_s = [0.0, 5.0]\n')
    d = drive(tmp_path, '[checks]\ncycles = ["UDDS"]\nWh_per_km_max = 500.0\n', name="d.toml")
    argv = {"run": ["run", "UDDS"], "check": ["check", str(d)], "study": ["study", str(spec)]}[cmd]
    t0 = time.perf_counter()
    r = cli(*argv, "--out", str(out))
    assert r.returncode == 2 and "--out" in r.err and str(out) in r.err and "Traceback" not in r.err, r.err
    assert time.perf_counter() - t0 < patient(30.0)   # refused before the cycle (minutes) ran
