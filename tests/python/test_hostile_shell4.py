"""The shell's round 4 (issue 35, the Python side): results that look right while they are wrong.
Each case runs the CLI in a child process with an address-space limit and a timeout, on
generated inputs, and must end right: exit 2 naming the file and the key, a gate that fails, a
FIFO left a FIFO, a DC link whose energy balance closes."""
from __future__ import annotations

import json
import math
import os
import random
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from scenarios.maps.flux_map import DEFAULT_MAP

from conftest import address_space_limit, patient

ROOT = Path(__file__).resolve().parents[2]
#: the child's address space: the Python side with fmpy, numpy, scipy and matplotlib loaded fits
AS_LIMIT = 4 << 30
TIMEOUT_S = patient(300)


def cli(*args: str, env: dict | None = None, timeout: float = TIMEOUT_S) -> subprocess.CompletedProcess:
    """python -m scenarios ARGS in a child with an address-space limit and a timeout."""
    return subprocess.run([sys.executable, "-m", "scenarios", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout, preexec_fn=address_space_limit(AS_LIMIT), env={**os.environ, **(env or {})})


def gentle_cycle(folder: Path, name: str = "c.csv", top: float = 8.0, duration: float = 12.0) -> Path:
    """Up to `top` m/s in 4 s, held, down to standstill over the last 4 s: any road car follows it."""
    p = folder / name
    p.write_text(f"time_s,speed_mps\n0,0\n4,{top}\n{duration - 4:g},{top}\n{duration:g},0\n")
    return p


def drive_file(folder: Path, body: str = "", checks: str = "", name: str = "d") -> Path:
    p = folder / f"{name}.toml"
    p.write_text(f'name = "{name}"\n[motor]\nflux_map = "{DEFAULT_MAP}"\n{body}\n'
                 + (f"[checks]\n{checks}\n" if checks else ""))
    return p


def closes(s: dict) -> None:
    """The DC link's energy balance within 1e-6 of its throughput, and no Wh/km below what the
    shaft's energy and the auxiliaries need (the drive's losses are >= 0)."""
    through = s["motor_electric_Wh"] + s["inverter_loss_Wh"] + s["aux_Wh"]
    assert abs(s["dc_link_residual_Wh"]) <= 1e-6 * max(abs(through), 1.0 / 3600), s["dc_link_residual_Wh"]
    E = s["energy_battery_Wh"]
    assert E == pytest.approx(s["motor_electric_Wh"] + s["inverter_loss_Wh"] + s["aux_Wh"] + s["regen_curtailed_Wh"],
                              rel=1e-6, abs=1e-9)
    assert E >= s["aux_Wh"] + s["shaft_Wh"] - 1e-9
    if s["Wh_per_km"] is not None:
        assert s["Wh_per_km"] >= (s["aux_Wh"] + s["shaft_Wh"]) / s["distance_km"] - 1e-9


# -- finding 1: energy from nothing ---------------------------------------------------------------
def test_a_weak_pack_limits_the_drive_and_the_gate_fails(tmp_path):
    """R0 = 20 Ohm (inside (0, 100]): past the pack's matched-load power the drive is held back,
    the car falls behind, the DC link closes, and `check` fails the cycle whatever limit it names."""
    c = gentle_cycle(tmp_path, top=25.0, duration=20.0)
    weak = drive_file(tmp_path, "[battery]\nR0 = 20.0", f'cycles = ["{c.name}"]\nWh_per_km_max = 1000.0', "weak")
    normal = drive_file(tmp_path, "", f'cycles = ["{c.name}"]\nWh_per_km_max = 1000.0', "normal")
    out = {}
    for d in (weak, normal):
        r = cli("run", str(c), "--drive", str(d), "--out", str(tmp_path / d.stem))
        assert r.returncode == 0, r.stderr
        out[d.stem] = json.loads((tmp_path / d.stem / "summary.json").read_text())
        closes(out[d.stem])
    w, n = out["weak"], out["normal"]
    assert w["time_battery_limited_s"] > 1.0 and n["time_battery_limited_s"] == 0.0
    assert w["distance_km"] < 0.8 * n["distance_km"]            # visibly behind
    r = cli("check", str(weak), "--out", str(tmp_path / "chk"), "--junit", str(tmp_path / "j.xml"))
    assert r.returncode == 1, r.stdout + r.stderr
    assert "FAIL weak/c.csv distance_km" in r.stdout and "cycle_distance_km_min" in (tmp_path / "j.xml").read_text()


DRIVES = sorted(p.name for p in (ROOT / "scenarios" / "drives").glob("*.toml"))


def random_run(tmp_path: Path, drive_name: str, seed: int) -> dict:
    """The drive with a random pack (R0 over three and a half decades, SOC0) on a random cycle of
    a few seconds."""
    from dataclasses import replace

    from scenarios.drives.description import DRIVES_DIR, load_drive
    from scenarios.runs.simulate import RunSpec, simulate
    rng = random.Random(seed)
    d = load_drive(DRIVES_DIR / drive_name)
    d = replace(d, battery=replace(d.battery, R0=10 ** rng.uniform(-2, 1.5), soc0=rng.uniform(0.2, 0.9)))
    c = gentle_cycle(tmp_path, top=rng.uniform(3.0, 30.0), duration=rng.uniform(8.0, 12.0))
    return simulate(str(c), RunSpec(drive=d, reference=False), progress=False).to_dict()


@pytest.mark.parametrize("drive_name", DRIVES)
def test_property_every_drive_and_a_random_pack_close_the_dc_link(tmp_path, drive_name):
    """Every shipped drive with a random pack and cycle: the DC link closes, no Wh/km below the
    shaft's (and so the wheel's) need."""
    closes(random_run(tmp_path, drive_name, DRIVES.index(drive_name)))


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(40))
def test_property_bigger(tmp_path, seed):
    closes(random_run(tmp_path, DRIVES[seed % len(DRIVES)], 1000 + seed))


# -- finding 2: units and ranges in the schema ----------------------------------------------------
@pytest.mark.parametrize("body, key", [
    ("[thermal]\nT_winding_max = 180", "thermal.T_winding_max"),
    ("[thermal]\nT_magnet_max = 300", "thermal.T_magnet_max"),
    ("[thermal]\nT_coolant = 90", "thermal.T_coolant"),
    ("[checks]\nsoc_end_min = 1.5", "checks.soc_end_min"),
])
def test_temperatures_in_degc_and_ranges_are_refused_naming_the_key(tmp_path, body, key):
    d = drive_file(tmp_path, body)
    r = cli("run", str(gentle_cycle(tmp_path)), "--drive", str(d), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and str(d) in r.stderr and key in r.stderr, r.stderr
    assert not (tmp_path / "o").exists()


def test_a_magnet_temperature_past_the_derating_zero_is_refused(tmp_path):
    r = cli("run", str(gentle_cycle(tmp_path)), "--magnet-degC", "160", "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "--magnet-degC" in r.stderr and "T_magnet_max" in r.stderr


def test_a_study_axis_of_booleans_is_refused():
    from scenarios.study.spec import SpecError, parse
    with pytest.raises(SpecError, match="thermal_models"):
        parse({"study": {"cycles": ["UDDS"], "thermal_models": [True]}})


# -- finding 7: outputs touch only what they own ---------------------------------------------------
def test_a_fifo_and_a_device_behind_junit_are_left_as_they_are(tmp_path):
    c = gentle_cycle(tmp_path)
    d = drive_file(tmp_path, "", f'cycles = ["{c.name}"]\nWh_per_km_max = 1000.0')
    fifo = tmp_path / "j.xml"
    os.mkfifo(fifo)
    r = cli("check", str(d), "--junit", str(fifo), "--out", str(tmp_path / "chk"))
    assert r.returncode == 2 and "--junit" in r.stderr and "FIFO" in r.stderr
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    link = tmp_path / "null.xml"
    link.symlink_to("/dev/null")
    r = cli("check", str(d), "--junit", str(link), "--out", str(tmp_path / "chk"))
    assert r.returncode == 2 and "device" in r.stderr and link.is_symlink()
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    dangling = tmp_path / "far.xml"
    dangling.symlink_to(tmp_path / "no" / "such" / "folder" / "j.xml")
    r = cli("check", str(d), "--junit", str(dangling), "--out", str(tmp_path / "chk"))
    assert r.returncode == 2 and not (tmp_path / "no").exists()


def test_a_fifo_in_the_out_folder_is_refused_before_the_run(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    os.mkfifo(out / "trace.csv")
    r = cli("run", str(gentle_cycle(tmp_path)), "--out", str(out))
    assert r.returncode == 2 and "trace.csv" in r.stderr and stat.S_ISFIFO(os.lstat(out / "trace.csv").st_mode)
    assert not (out / "summary.json").exists()


def test_a_run_folder_holds_one_run_and_is_locked(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "thermal.png").write_bytes(b"a previous run's")
    r = cli("run", str(gentle_cycle(tmp_path)), "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert not (out / "thermal.png").exists() and (out / "summary.json").is_file()
    assert all(p.stat().st_mode & 0o777 == 0o644 for p in out.iterdir())
    import fcntl
    with open(out / ".run.lock", "w") as held:  # a run in progress
        fcntl.flock(held, fcntl.LOCK_EX)
        r = cli("run", str(gentle_cycle(tmp_path)), "--out", str(out))
    assert r.returncode == 2 and "lock" in r.stderr


def test_a_failed_run_leaves_no_folder_it_made(tmp_path):
    d = drive_file(tmp_path, "[battery]\nsoc0 = 0.0")   # empty at the first step
    r = cli("run", str(gentle_cycle(tmp_path)), "--drive", str(d), "--out", str(tmp_path / "new"))
    assert r.returncode != 0 and not (tmp_path / "new").exists()


# -- finding 8: a valid R_s ------------------------------------------------------------------------
def test_a_high_stator_resistance_runs_to_the_end(tmp_path):
    d = drive_file(tmp_path, name="rs")
    d.write_text(d.read_text().replace("[motor]\n", "[motor]\nR_s = 0.5\n"))  # declared (0, 1000]
    c = gentle_cycle(tmp_path, top=6.0, duration=20.0)
    r = cli("run", str(c), "--drive", str(d), "--out", str(tmp_path / "o"))
    assert r.returncode == 0, r.stderr
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert math.isfinite(s["current_excess_rms_A"]) and s["copper_loss_optimal_Wh"] > 0.0
    closes(s)


# -- item 6: --repeat inside the cycle cap --------------------------------------------------------
def test_repeat_past_the_week_cap_is_refused(tmp_path):
    c = tmp_path / "six_days.csv"
    c.write_text("time_s,speed_mps\n0,0\n518400,0\n")
    r = cli("run", str(c), "--repeat", "100", "--out", str(tmp_path / "o"), timeout=patient(60))
    assert r.returncode == 2 and "--repeat" in r.stderr and not (tmp_path / "o").exists()


# -- finding 5: the import cache -------------------------------------------------------------------
def test_the_import_cache_is_verified_owned_and_optional(tmp_path, monkeypatch):
    from scenarios.maps import import_cache
    from scenarios.maps.flux_map import read_flux_map, write_flux_map
    fmap = read_flux_map(DEFAULT_MAP)
    half = tmp_path / "half.csv"   # the upper half-plane: the importer mirrors it (needs the cache)
    keep = fmap.i_q >= 0.0
    from scenarios.maps.flux_map import FluxMap
    write_flux_map(half, FluxMap(fmap.i_d, fmap.i_q[keep], fmap.psi_d[:, keep], fmap.psi_q[:, keep], fmap.metadata))
    cache = tmp_path / "cache"
    monkeypatch.setenv("IPMSM_MAP_CACHE", str(cache))
    first = import_cache.contract_csv(half)
    assert first.parent == cache and import_cache.trusted(first)
    first.write_text(first.read_text().replace("0.", "0.0", 1))   # edited after the import
    again = import_cache.contract_csv(half)
    assert import_cache.trusted(again) and again.read_bytes() != b""
    cache.chmod(0o777)   # anybody may write: not used
    elsewhere = import_cache.contract_csv(half)
    assert elsewhere.parent != cache
    cache.chmod(0o700)
    monkeypatch.setenv("IPMSM_MAP_CACHE", "/proc/no-such-cache")   # cannot be made: optional
    assert import_cache.contract_csv(half).is_file()


# -- the "Unclear" list: labels, escapes, modes ----------------------------------------------------
def test_junit_labels_that_look_alike_are_told_apart(tmp_path):
    """A file UDDS beside the standard UDDS, NFC beside NFD, a trailing space: distinct labels."""
    import unicodedata

    from scenarios.drives.description import load_drive
    from scenarios.runs.check import _look, cycle_labels
    nfc = unicodedata.normalize("NFC", "caf\u00e9.csv")
    nfd = unicodedata.normalize("NFD", nfc)
    for name in ("UDDS", nfc, nfd, "town.csv", "town.csv "):
        gentle_cycle(tmp_path, name)
    d = drive_file(tmp_path, "", 'cycles = ["UDDS", "./UDDS", "' + nfc + '", "' + nfd + '", "town.csv", "town.csv "]\n'
                   "Wh_per_km_max = 1000.0")
    labels = cycle_labels(load_drive(d))
    assert len(labels) == 6
    looks = [_look(v) for v in labels.values()]
    assert len(set(looks)) == len(looks), labels


def test_a_cycle_name_with_escape_sequences_is_shown_not_obeyed(tmp_path, capsys):
    from scenarios.core.progress import Progress
    bar = Progress(1, "c\x1b[2J\x1b]0;owned\x07")
    bar.update()
    bar.close()
    err = capsys.readouterr().err
    assert "\x1b" not in err and "\x07" not in err and "\\x1b" in err


def test_map_import_writes_0644_whatever_the_umask(tmp_path):
    out = tmp_path / "imported.csv"
    old = os.umask(0o077)
    try:
        r = cli("map", "import", str(DEFAULT_MAP), "--out", str(out))
    finally:
        os.umask(old)
    assert r.returncode == 0, r.stderr
    assert out.stat().st_mode & 0o777 == 0o644


def test_a_grid_of_three_points_and_an_all_zero_map_are_refused_with_exit_2(tmp_path):
    lines = DEFAULT_MAP.read_text().splitlines()
    head = [x for x in lines if x.startswith("#") or x.startswith("i_d")]
    rows = [x.split(",") for x in lines if x and not x.startswith("#") and not x.startswith("i_d")]
    ids = sorted({float(r[0]) for r in rows})
    iqs = sorted({float(r[1]) for r in rows})
    keep_d, keep_q = {ids[0], ids[len(ids) // 2], ids[-1]}, {iqs[0], iqs[len(iqs) // 2], iqs[-1]}
    g3 = tmp_path / "g3.csv"
    g3.write_text("\n".join(head + [",".join(r) for r in rows if float(r[0]) in keep_d and float(r[1]) in keep_q]))
    zero = tmp_path / "zero.csv"
    zero.write_text("\n".join(head + [f"{r[0]},{r[1]},0,0" for r in rows]))
    for m in (g3, zero):
        for cmd in (["map", "check", str(m), "--out", str(tmp_path / "o")],
                    ["map", "repair", str(m), "--out", str(tmp_path / "r.csv")]):
            r = cli(*cmd)
            assert r.returncode == 2 and str(m) in r.stderr and "Traceback" not in r.stderr, (cmd, r.stderr)


def test_a_junk_fmu_under_build_is_refused_naming_it(tmp_path):
    (tmp_path / "b" / "fmu").mkdir(parents=True)
    for n in ("IpmsmController", "IpmsmPlant", "IpmsmDrive"):
        (tmp_path / "b" / "fmu" / f"{n}.fmu").write_bytes(b"junk")
    r = cli("--build", str(tmp_path / "b"), "run", str(gentle_cycle(tmp_path)), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "--build" in r.stderr and ".fmu" in r.stderr


def test_junit_folders_are_never_made_through_a_link(tmp_path):
    c = gentle_cycle(tmp_path)
    d = drive_file(tmp_path, "", f'cycles = ["{c.name}"]\nWh_per_km_max = 1000.0')
    far = tmp_path / "far"
    far.mkdir()
    (tmp_path / "near").symlink_to(far)
    r = cli("check", str(d), "--junit", str(tmp_path / "near" / "new" / "j.xml"), "--out", str(tmp_path / "chk"))
    assert r.returncode == 2 and "--junit" in r.stderr and not (far / "new").exists()
    r = cli("check", str(d), "--junit", str(tmp_path / "reports" / "ci" / "j.xml"), "--out", str(tmp_path / "chk"))
    assert r.returncode == 0, r.stderr   # missing folders on a path without links: made
    assert (tmp_path / "reports" / "ci" / "j.xml").is_file()
