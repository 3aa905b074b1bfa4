"""Drive descriptions (scenarios.drives.description, docs/drives.md): every key of the schema
changes a run; bad files are refused with the file, the key and the expectation, exit status 2
and nothing written; the default drive is what no --drive means; the second example drive's
consumption is in its published range."""
from __future__ import annotations

import dataclasses
import functools
import pickle
import shutil
from pathlib import Path

import pytest

from scenarios import __main__ as cli
from scenarios.core.paths import ROOT
from scenarios.drives.description import (
    DEFAULT_DRIVE,
    DRIVES_DIR,
    INVERTER_KEYS,
    SCHEMA,
    DriveDescriptionError,
    Key,
    controller_has_objective,
    load_drive,
    schema_markdown,
)
from scenarios.maps.flux_map import DEFAULT_MAP
from scenarios.runs.simulate import Conditions, RunSpec, simulate
from scenarios.vehicle.cycles import load_cycle, segment

from conftest import fmu_path

CITY_EV = DRIVES_DIR / "city_ev.toml"

#: a window with traction and regenerative braking to a stop: US06 t = 26..44 s (a flying start
#: at 65 km/h, down to 62 km/h and up to 63 km/h, then 62 -> 0 km/h in 8 s)
WINDOW = ("US06", 26.0, 44.0)


def toml_text(doc: dict) -> str:
    """The few TOML forms the tests need: top-level scalars, then [tables] of scalars and lists."""
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)
    lines = [f"{k} = {value(v)}" for k, v in doc.items() if not isinstance(v, dict)]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += [f"[{k}]"] + [f"{kk} = {value(vv)}" for kk, vv in v.items()]
    return "\n".join(lines) + "\n"


def write_drive(tmp_path: Path, doc: dict, name: str = "drive.toml") -> Path:
    doc = {**doc, "motor": {"flux_map": str(DEFAULT_MAP), **doc.get("motor", {})}}
    path = tmp_path / name
    path.write_text(toml_text(doc))
    return path


# -- every key changes a run ---------------------------------------------------------------------
#: perturbed values where "the default times 1.25" would not do (outside the key's range, no
#: effect in the window, or not a number); the rest are perturbed generically
PERTURBED = {
    "name": "perturbed",
    "motor.flux_map": str(DRIVES_DIR / "city_ev_motor.csv"),
    "motor.k_psi_T": -0.003,
    "motor.T_magnet_ref": 313.15,
    "motor.T_winding_ref": 313.15,
    "motor.fe_alpha": 1.6,
    "battery.soc0": 0.8,
    "battery.ocv": "pybamm_ecm_example",
    "battery.u_cell_max": 3.71,        # just above the pack's 3.705 V/cell at SOC 0.5: regen is capped
    "vehicle.driveline_efficiency": 0.9,
    "vehicle.tyre_road_friction": 0.01,  # friction brakes limited to 0.01 m g
    "controller.method": "lut_flux",
    "controller.recursion": 1,
    "controller.k_u": 0.8,
    "controller.current_bandwidth": 1000.0,
    "controller.command_check": 0,
    "controller.objective": "loss",
    "vehicle.grade": 0.05,
    "thermal.thermal_model": True,
    "thermal.k_fe_yoke": 0.5,
    "thermal.T_magnet_estimate_error": 10.0,
}

#: keys that act only under some condition: the condition the test runs them in, as RunSpec
#: fields ("spec") and keys of the drive ("drive"), for the baseline and the perturbed run alike
CONDITIONS = {
    "motor.k_psi_T": {"spec": dict(conditions=Conditions("hot magnets", T_magnet=393.15, T_winding=293.15))},
    "motor.alpha_cu": {"spec": dict(conditions=Conditions("hot winding", T_magnet=293.15, T_winding=393.15))},
    "motor.w_m_max": {"spec": dict(method="lut_speed")},
    "controller.lut_u_dc": {"spec": dict(method="lut_speed")},
    # the check replaces only commands that fail it: the 2-D tables' do
    "controller.command_check": {"spec": dict(method="lut_speed")},
    # a full battery takes no regenerative braking: the friction brakes do all of it
    "vehicle.tyre_road_friction": {"drive": {"battery": {"soc0": 1.0}}},
}
# the thermal network's keys act with it on (a coolant away from 20 degC: k_coolant_yoke acts)
CONDITIONS.update({k.path: {"drive": {"thermal": {"thermal_model": True, "T_coolant": 338.15}}} for k in SCHEMA
                   if k.section == "thermal" and k.name != "thermal_model"})
# the controller's derating acts near its maximum temperatures: a hot winding (magnets cool), hot magnets
HOT_WINDING = Conditions("hot winding, derated", T_magnet=293.15, T_winding=448.15)
CONDITIONS.update({"thermal.T_winding_max": {"spec": dict(conditions=HOT_WINDING)},
                   "thermal.derating_margin": {"spec": dict(conditions=HOT_WINDING)},
                   "thermal.T_magnet_max": {"spec": dict(conditions=Conditions("hot magnets, derated", T_magnet=418.15,
                                                                               T_winding=293.15))}})

# the [fault] keys need a trigger beside them: tests/python/test_fault_scenarios.py perturbs each
RUN_KEYS = [k for k in SCHEMA if k.section not in ("checks", "fault")]


@functools.lru_cache(maxsize=1)
def default_drive():
    return load_drive()


def perturbed_value(key: Key):
    if key.section == "thermal" and default_drive().value(key.path) is None:
        return None  # a key of FMUs newer than the build's (derating, before it was built)
    if key.path == "controller.objective" and not controller_has_objective():
        return None  # least loss, before its FMUs are built
    if key.path in PERTURBED:
        return PERTURBED[key.path]
    d = default_drive()
    v = d.value(key.path)
    if v is None and key.path == "motor.w_m_max":
        v = 1256.6370614359173  # the controller FMU's default: perturb from there
    return v + 1 if key.rule.kind == "int" else v * 1.25


def run_window(drive, fmus, **spec) -> dict:
    cycle = segment(load_cycle(WINDOW[0]), *WINDOW[1:])
    s = simulate(cycle, RunSpec(drive=drive, backend="drive", reference=False, **spec), fmus=fmus, progress=False)
    d = s.to_dict()
    for k in ("wall_s", "real_time_factor", "drive_sha256"):
        d.pop(k)
    return d


def merged(doc: dict, overlay: dict) -> dict:
    out = dict(doc)
    for k, v in overlay.items():
        out[k] = {**out.get(k, {}), **v} if isinstance(v, dict) else v
    return out


@pytest.fixture(scope="module")
def baselines(controller_fmu, plant_fmu):
    cache = {}

    def get(condition_key: str | None, tmp: Path):
        if condition_key not in cache:
            cond = CONDITIONS.get(condition_key, {})
            doc = merged({"name": "default"}, cond.get("drive", {}))
            drive = load_drive(write_drive(tmp, doc, "base.toml"))
            cache[condition_key] = run_window(drive, (controller_fmu, plant_fmu), **cond.get("spec", {}))
        return cache[condition_key]
    return get


def test_every_run_key_is_perturbed_or_generic():
    """A new key gets a perturbation (generic: 1.25 x its default) and so a run in the test below."""
    for k in RUN_KEYS:
        v = perturbed_value(k)
        assert v is None or k.rule.check(v) is None, (k.path, v, k.rule.check(v))


@pytest.mark.parametrize("key", RUN_KEYS, ids=[k.path for k in RUN_KEYS])
def test_every_key_changes_the_run(key, tmp_path, baselines, controller_fmu, plant_fmu):
    value = perturbed_value(key)
    if value is None:
        pytest.skip(f"the built FMUs have no {key.name}")
    doc = {"name": "default"}
    if key.section:
        doc[key.section] = {key.name: value}
    else:
        doc[key.name] = value
    cond = CONDITIONS.get(key.path)
    drive = load_drive(write_drive(tmp_path, merged((cond or {}).get("drive", {}), doc)))
    base = baselines(key.path if cond else None, tmp_path)
    got = run_window(drive, (controller_fmu, plant_fmu), **(cond or {}).get("spec", {}))
    changed = sorted(k for k in got if got[k] != base[k])
    assert changed, f"{key.path} = {value!r} changed nothing in the summary ({key.acts})"


def test_the_reference_optimum_uses_the_drives_motor(controller_fmu, plant_fmu):
    """Ferrari with recursion 2 is the optimum: its copper loss equals the reference's on the
    city drive's 12-pole motor too (a reference on the default motor would be far off)."""
    cycle = segment(load_cycle("UDDS"), 180.0, 220.0)
    s = simulate(cycle, RunSpec(drive=load_drive(CITY_EV), backend="drive"), fmus=(controller_fmu, plant_fmu),
                 progress=False)
    assert s.drive == "city_ev"
    assert s.copper_loss_optimal_Wh == pytest.approx(s.copper_loss_Wh, rel=0.01)


# -- the default drive ---------------------------------------------------------------------------
def test_default_drive_is_the_dataclasses_defaults():
    """default.toml names only the map: every value is the vehicle side's dataclass default, the
    FMUs' own default (the inverter's) or the default map's metadata, so there is one place for
    each number."""
    from scenarios.core.fmu_ranges import read_starts
    from scenarios.maps.flux_map import MotorData, read_flux_map
    from scenarios.vehicle.battery import BatteryParams
    from scenarios.vehicle.longitudinal import VehicleParams
    d = load_drive(None)
    assert d.source == DEFAULT_DRIVE and d.name == "default"
    assert d.vehicle == VehicleParams() and d.battery == BatteryParams()
    # the inverter's: the plant FMU's and the drive FMU's own defaults (one C++ table), by the same names
    assert d.inverter == {k: v for k, v in read_starts(fmu_path("IpmsmDrive")).items() if k in INVERTER_KEYS}
    assert set(d.inverter) == set(INVERTER_KEYS) and d.inverter["f_sw"] == 10e3
    assert d.motor_data() == MotorData.of(read_flux_map(DEFAULT_MAP))
    assert d.controller.current_bandwidth is None  # the FMU's own default
    assert d.motor.w_m_max == read_flux_map(DEFAULT_MAP).number("w_m_max_rad_s")  # the map's top speed
    assert d.assumed == ()  # the default motor's map gives every value
    assert pickle.loads(pickle.dumps(d)) == d


def test_no_drive_and_the_default_drive_give_the_same_run(tmp_path, controller_fmu, plant_fmu):
    """`run` without --drive and with scenarios/drives/default.toml: the same summary, bit for bit."""
    cycle = segment(load_cycle("WLTC3b"), 0.0, 20.0)
    a = simulate(cycle, RunSpec(), fmus=(controller_fmu, plant_fmu), progress=False).to_dict()
    b = simulate(cycle, RunSpec(drive=load_drive(DEFAULT_DRIVE)), fmus=(controller_fmu, plant_fmu),
                 progress=False).to_dict()
    for d in (a, b):
        d.pop("wall_s"), d.pop("real_time_factor")
    assert a == b and a["drive"] == "default" and len(a["drive_sha256"]) == 64


def test_paths_are_relative_to_the_file_and_ocv_takes_a_csv(tmp_path):
    shutil.copy(DRIVES_DIR / "city_ev_motor.csv", tmp_path / "m.csv")
    import csv

    from scenarios.vehicle.battery import OCV_CSV, OCV_FITS, Ocv
    rows = list(csv.DictReader(open(OCV_CSV)))
    (tmp_path / "ocv.csv").write_text("soc,ocv_cell_V\n" + "".join(
        f"{r['soc']},{r[OCV_FITS['chen2020']]}\n" for r in rows))
    path = tmp_path / "d.toml"
    path.write_text('[motor]\nflux_map = "m.csv"\n[battery]\nocv = "ocv.csv"\n')
    d = load_drive(path)
    assert d.motor.flux_map == tmp_path / "m.csv" and d.motor.pole_pairs == 6   # from the map's metadata
    assert d.battery.ocv_csv == tmp_path / "ocv.csv"
    assert Ocv(d.battery)(0.5) == Ocv(load_drive().battery)(0.5)   # the same curve from the user's CSV


def test_docs_hold_the_schema():
    """docs/drives.md carries the schema table as the code has it."""
    assert schema_markdown() in (ROOT / "docs" / "drives.md").read_text()


def test_city_ev_map_is_what_its_generator_makes(tmp_path):
    from tools.make_city_ev_map import write
    write(tmp_path / "m.csv")
    assert (tmp_path / "m.csv").read_text() == (DRIVES_DIR / "city_ev_motor.csv").read_text()


# -- bad descriptions ----------------------------------------------------------------------------
BAD = {
    # name: (file text, the key the error must name, words of the expectation)
    "unknown key": ('[motor]\nflux_map = "{map}"\n[vehicle]\ngear_ratoi = 8.0\n', "vehicle.gear_ratoi",
                    "gear_ratio"),
    "unknown table": ('[motor]\nflux_map = "{map}"\n[vehicel]\nmass = 1500.0\n', "vehicel", "vehicle"),
    "string for a number": ('[motor]\nflux_map = "{map}"\n[vehicle]\nmass = "1500 kg"\n', "vehicle.mass",
                            "a number"),
    "bool for a number": ('[motor]\nflux_map = "{map}"\n[vehicle]\nmass = true\n', "vehicle.mass", "a number"),
    "float for an integer": ('[motor]\nflux_map = "{map}"\n[battery]\nn_series = 96.0\n', "battery.n_series",
                             "an integer"),
    "SOC in percent": ('[motor]\nflux_map = "{map}"\n[battery]\nsoc0 = 50\n', "battery.soc0", "[0, 1]"),
    "gear ratio zero": ('[motor]\nflux_map = "{map}"\n[vehicle]\ngear_ratio = 0.0\n', "vehicle.gear_ratio",
                        "[0.1, 100]"),
    "gear ratio negative": ('[motor]\nflux_map = "{map}"\n[vehicle]\ngear_ratio = -8.19\n', "vehicle.gear_ratio",
                            "[0.1, 100]"),
    "mass zero": ('[motor]\nflux_map = "{map}"\n[vehicle]\nmass = 0\n', "vehicle.mass", "[1, 100000]"),
    "no cells": ('[motor]\nflux_map = "{map}"\n[battery]\nn_series = 0\n', "battery.n_series", "[1, 10000]"),
    "efficiency above one": ('[motor]\nflux_map = "{map}"\n[vehicle]\ndriveline_efficiency = 1.2\n',
                             "vehicle.driveline_efficiency", "(0, 1]"),
    "unknown method": ('[motor]\nflux_map = "{map}"\n[controller]\nmethod = "newton"\n', "controller.method",
                       "ferrari"),
    "unknown OCV": ('[motor]\nflux_map = "{map}"\n[battery]\nocv = "lfp"\n', "battery.ocv", "chen2020"),
    "no flux map": ('name = "x"\n[vehicle]\nmass = 1500.0\n', "motor.flux_map", "flux-map file"),
    "missing map": ('[motor]\nflux_map = "nowhere.csv"\n', "motor.flux_map", "nowhere.csv"),
    "malformed map": ('[motor]\nflux_map = "bad_map.csv"\n', "motor.flux_map", "i_d,i_q,psi_d,psi_q"),
    "incomplete map": ('[motor]\nflux_map = "holey_map.csv"\n', "motor.flux_map", "rectangular grid"),
    "TOML syntax": ('[motor\nflux_map = "{map}"\n', "(syntax)", "valid TOML"),
    "unknown cycle": ('[motor]\nflux_map = "{map}"\n[checks]\ncycles = ["FTP-99"]\n', "checks.cycles",
                      "FTP-99"),
}


@pytest.fixture
def bad_drive(tmp_path):
    def make(case: str) -> tuple[Path, str, str]:
        text, key, words = BAD[case]
        (tmp_path / "bad_map.csv").write_text("# a map with the wrong header\nid,iq,psid,psiq\n0,0,0.07,0\n")
        grid = [(d, q) for d in (0, 10, 20) for q in (0, 10) if (d, q) != (20, 10)]   # one point missing
        rows = "".join(f"{d},{q},{0.07 + 1e-4 * d},{1e-4 * q}\n" for d, q in grid)
        (tmp_path / "holey_map.csv").write_text("i_d,i_q,psi_d,psi_q\n" + rows)
        path = tmp_path / "bad.toml"
        path.write_text(text.replace("{map}", str(DEFAULT_MAP)))
        return path, key, words
    return make


@pytest.mark.parametrize("case", list(BAD))
def test_bad_description_names_file_key_and_expectation(case, bad_drive):
    path, key, words = bad_drive(case)
    with pytest.raises(DriveDescriptionError) as e:
        load_drive(path)
    assert (Path(e.value.file), e.value.key) == (path, key)
    assert words in e.value.expected and str(path) in str(e.value) and key in str(e.value)


@pytest.mark.parametrize("cmd", ["run", "sweep", "check"])
@pytest.mark.parametrize("case", ["unknown key", "gear ratio zero", "malformed map", "TOML syntax"])
def test_cli_exits_2_and_writes_nothing(cmd, case, bad_drive, tmp_path, capsys):
    path, key, _ = bad_drive(case)
    out = tmp_path / "out"
    argv = {"run": ["run", "UDDS", "--drive", str(path), "--out", str(out)],
            "sweep": ["sweep", "--drive", str(path), "--out", str(out)],
            "check": ["check", str(path), "--out", str(out), "--junit", str(out / "report.xml")]}[cmd]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert str(path) in err and key in err
    assert not out.exists()


def test_bad_description_error_survives_pickling():
    e = DriveDescriptionError(Path("/x.toml"), "vehicle.mass", "a number > 0")
    f = pickle.loads(pickle.dumps(e))
    assert (f.file, f.key, f.expected, str(f)) == (e.file, e.key, e.expected, str(e))


# -- the second example drive in its published range ---------------------------------------------
#: battery-DC Wh/km of the city EV's class: docs/drives.md ("Published range")
CITY_EV_PUBLISHED = {"UDDS": (86.0, 107.0), "HWFET": (106.0, 132.0)}


@pytest.mark.slow
@pytest.mark.parametrize("cycle", list(CITY_EV_PUBLISHED))
def test_city_ev_consumption_in_published_range(cycle, controller_fmu, plant_fmu):
    s = simulate(cycle, RunSpec(drive=load_drive(CITY_EV), backend="drive"), fmus=(controller_fmu, plant_fmu),
                 progress=False)
    lo, hi = CITY_EV_PUBLISHED[cycle]
    print(f"\n[city_ev {cycle}] {s.Wh_per_km:.1f} Wh/km ({lo:g}-{hi:g}), {s.wall_s:.1f} s")
    assert lo <= s.Wh_per_km <= hi
    assert s.speed_rmse_mps < 0.2


def test_city_ev_is_a_different_car_and_motor():
    a, b = load_drive(), load_drive(CITY_EV)
    assert b.motor.pole_pairs != a.motor.pole_pairs and b.vehicle.mass < 0.8 * a.vehicle.mass
    assert dataclasses.replace(b, name=a.name) != a



def test_a_drive_may_name_a_fem_export(tmp_path, monkeypatch):
    """motor.flux_map = a Motor-CAD .mat (peak d/q grid): imported to a cached contract CSV that
    holds the same machine; a .mat without the fields is an error of the description."""
    import numpy as np
    import scipy.io as sio

    from scenarios.maps.flux_map import read_flux_map
    monkeypatch.setenv("IPMSM_MAP_CACHE", str(tmp_path / "cache"))
    f = read_flux_map(DEFAULT_MAP)
    I_d, I_q = np.meshgrid(f.i_d, f.i_q, indexing="ij")
    sio.savemat(tmp_path / "motor.mat", dict(Id_Peak=I_d, Iq_Peak=I_q, Flux_Linkage_D=f.psi_d, Flux_Linkage_Q=f.psi_q))
    (tmp_path / "d.toml").write_text('[motor]\nflux_map = "motor.mat"\n')
    d = load_drive(tmp_path / "d.toml")
    assert d.motor.flux_map.parent == tmp_path / "cache" and d.motor.flux_map.suffix == ".csv"
    g = read_flux_map(d.motor.flux_map)
    assert np.array_equal(g.i_d, f.i_d) and np.allclose(g.psi_q, f.psi_q, rtol=0, atol=1e-12)
    sio.savemat(tmp_path / "motor.mat", dict(Id_Peak=I_d, Iq_Peak=I_q))
    with pytest.raises(DriveDescriptionError) as e:
        load_drive(tmp_path / "d.toml")
    assert e.value.key == "motor.flux_map" and "motor.mat" in str(e.value)


def test_the_drive_fmu_backend_follows_the_drive_too(controller_fmu, plant_fmu):
    """--backend drive (the IpmsmDrive FMU, inverter inside) on the city EV: the same energy as the
    two FMUs in the reference loop with the Python inverter model, so its motor and inverter
    parameters came from the file."""
    cycle = segment(load_cycle(WINDOW[0]), *WINDOW[1:])
    drive = load_drive(CITY_EV)
    a, b = (simulate(cycle, RunSpec(drive=drive, backend=backend, reference=False), fmus=(controller_fmu, plant_fmu),
                     progress=False) for backend in ("fmpy", "drive"))
    assert b.backend == "drive" and b.Wh_per_km == pytest.approx(a.Wh_per_km, rel=1e-9)
    assert b.iron_loss_Wh == pytest.approx(a.iron_loss_Wh, rel=1e-9)
