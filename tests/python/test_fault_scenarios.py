"""The scenarios side of a fault (docs/faults.md): the drive description's [fault] table and its
refusals, the trigger, a run with a trip (its summary keys, its trace and picture, the driver
without traction, the energy balances closing through the fault), the check limits on the
fault's figures, and `sweep --fault` (its rows against the map's own steady state).

The tests that run IpmsmDrive need its `fault` input (contract, "Faults"): they are skipped on
FMUs built without it, and run on every build that has it."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from scenarios import __main__ as cli
from scenarios.core.boundary import InputError
from scenarios.drives.description import (
    DRIVES_DIR,
    FAULT_LIMITS,
    SCHEMA,
    DriveDescriptionError,
    FaultSpec,
    load_drive,
)
from scenarios.maps.flux_map import DEFAULT_MAP, read_flux_map
from scenarios.runs.check import CYCLE_FOLLOWING, CYCLE_SPEED_RMSE_MAX, judge
from scenarios.runs.fault import FaultTrigger
from scenarios.vehicle.cycles import load_cycle, segment

from conftest import fmu_path

TRIP = DRIVES_DIR / "trip.toml"
RPM = math.pi / 30.0


def write(tmp_path: Path, body: str, name: str = "d.toml") -> Path:
    """A drive of the default map and `body` (its lines before the first table: top-level keys)."""
    lines = body.splitlines(keepends=True)
    k = next((i for i, x in enumerate(lines) if x.startswith("[")), len(lines))
    p = tmp_path / name
    p.write_text("".join(lines[:k]) + f'name = "f"\n[motor]\nflux_map = "{DEFAULT_MAP}"\n' + "".join(lines[k:]))
    return p


# -- the [fault] table ----------------------------------------------------------------------------
def test_the_trip_drive_loads_as_its_file_says():
    d = load_drive(TRIP)
    assert d.fault == FaultSpec(trigger="v_kmh", at=130.0, safe_state="by_speed")
    assert d.thermal.on and d.checks.cycles == ("WLTC3b",)
    assert d.fault.fmu_params() == {"safe_state": 0}


def test_wltc3b_reaches_130_kmh_once_in_its_extra_high_phase():
    """trip.toml's claim about the cycle: the trace first reaches 130 km/h between 1719 and 1720 s,
    its top is 131.3 km/h at 1724 s."""
    c = load_cycle("WLTC3b")
    kmh = np.asarray(c.speed_mps) * 3.6
    t = np.asarray(c.time_s)
    first = t[np.argmax(kmh >= 130.0)]
    assert first == 1720.0 and kmh[t == 1719.0][0] < 130.0
    assert kmh.max() == pytest.approx(131.3, abs=1e-3) and t[np.argmax(kmh)] == 1724.0
    assert kmh[t < 1716.0].max() < 130.0


@pytest.mark.parametrize("body, value", [
    ("t_s = 12.5\n", FaultSpec("t_s", 12.5)),
    ("speed_rpm = 9000.0\nsafe_state = \"asc\"\n", FaultSpec("speed_rpm", 9000.0, "asc")),
    ("v_kmh = 100\nsafe_state = \"freewheel\"\nduration_s = 2.5\ni_d_demag = -800.0\n",
     FaultSpec("v_kmh", 100.0, "freewheel", 2.5, -800.0)),
])
def test_each_trigger_and_key_loads(tmp_path, body, value):
    d = load_drive(write(tmp_path, "[fault]\n" + body))
    assert d.fault == value
    for k in ("t_s", "speed_rpm", "v_kmh", "safe_state", "duration_s", "i_d_demag"):
        assert d.value(f"fault.{k}") == value.value(k)


BAD = {
    # name: ([fault] body and [checks] body, key named, words of the expectation)
    "no trigger": ("[fault]\nsafe_state = \"asc\"\n", "fault", "exactly one trigger"),
    "two triggers": ("[fault]\nt_s = 1.0\nv_kmh = 100.0\n", "fault.v_kmh", "exactly one trigger"),
    "three triggers": ("[fault]\nt_s = 1.0\nspeed_rpm = 5.0\nv_kmh = 100.0\n", "fault.speed_rpm", "exactly one"),
    "unknown key": ("[fault]\nt_s = 1.0\nspeed = 3.0\n", "fault.speed", "fault.speed_rpm"),
    "unknown state": ("[fault]\nt_s = 1.0\nsafe_state = \"ASC\"\n", "fault.safe_state", "'asc'"),
    "state as a number": ("[fault]\nt_s = 1.0\nsafe_state = 2\n", "fault.safe_state", "'by_speed'"),
    "negative time": ("[fault]\nt_s = -1.0\n", "fault.t_s", ">= 0"),
    "zero speed": ("[fault]\nv_kmh = 0.0\n", "fault.v_kmh", "> 0"),
    "nan speed": ("[fault]\nspeed_rpm = nan\n", "fault.speed_rpm", "a number"),
    "zero duration": ("[fault]\nt_s = 1.0\nduration_s = 0.0\n", "fault.duration_s", "(0,"),
    "positive i_d_demag": ("[fault]\nt_s = 1.0\ni_d_demag = 100.0\n", "fault.i_d_demag", "0)"),
    "string time": ("[fault]\nt_s = \"12 s\"\n", "fault.t_s", "a number"),
    "not a table": ("fault = 3\n", "fault", "a table"),
    **{f"{lim} without a fault": (f"[checks]\ncycles = [\"UDDS\"]\n{lim} = 1.0\n", f"checks.{lim}", "[fault] table")
       for lim in FAULT_LIMITS},
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_fault_table_is_refused_naming_file_and_key(case, tmp_path):
    body, key, words = BAD[case]
    p = write(tmp_path, body)
    with pytest.raises(DriveDescriptionError) as e:
        load_drive(p)
    assert (Path(e.value.file), e.value.key) == (p, key), str(e.value)
    assert words in e.value.expected, e.value.expected


@pytest.mark.parametrize("case", ["two triggers", "unknown state", "fault_i_peak_A_max without a fault"])
def test_the_cli_exits_2_naming_file_and_key(case, tmp_path, capsys):
    body, key, _ = BAD[case]
    p = write(tmp_path, body)
    out = tmp_path / "out"
    assert cli.main(["run", "UDDS", "--drive", str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(p) in err and key in err
    assert not out.exists()


def test_the_schema_documents_every_fault_key():
    keys = {k.name for k in SCHEMA if k.section == "fault"}
    assert keys == {"t_s", "speed_rpm", "v_kmh", "safe_state", "duration_s", "i_d_demag"}
    text = (Path(__file__).parents[2] / "docs" / "faults.md").read_text()
    for k in keys:
        assert f"`{k}`" in text, k


# -- the trigger ----------------------------------------------------------------------------------
def _first_on(spec: FaultSpec, ts, vs, ws):
    trig = FaultTrigger(spec)
    on = [trig.on(t, v, w) for t, v, w in zip(ts, vs, ws)]
    return on, trig


def test_a_time_trigger_fires_at_the_first_point_at_or_after_it_and_lasts_its_duration():
    ts = [k * 0.01 for k in range(1000)]   # rounding: 0.01 * 250 is not 2.5 exactly
    on, trig = _first_on(FaultSpec("t_s", 2.5, duration_s=1.0), ts, [0.0] * 1000, [0.0] * 1000)
    assert on.index(True) == 250 and trig.t_start == ts[250]
    assert sum(on) == 100 and not any(on[350:])
    on, _ = _first_on(FaultSpec("t_s", 2.505), ts, [0.0] * 1000, [0.0] * 1000)
    assert on.index(True) == 251 and all(on[251:])   # no duration: to the end


def test_a_speed_trigger_fires_where_the_speed_is_reached_and_once():
    v = [30.0, 35.0, 36.0, 36.2, 36.5, 30.0, 37.0]   # m/s: 130 km/h is 36.11 m/s
    on, trig = _first_on(FaultSpec("v_kmh", 130.0, duration_s=0.015), [0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06], v,
                         [0.0] * 7)
    assert on == [False, False, False, True, True, False, False]   # one fault per run
    assert trig.v_start == 36.2
    w = [100.0, 900.0, 943.0, 950.0]   # rad/s: 9000 r/min is 942.48 rad/s
    on, trig = _first_on(FaultSpec("speed_rpm", 9000.0), [0, 1, 2, 3], [0.0] * 4, w)
    assert on == [False, False, True, True] and trig.w_m_start == 943.0
    on, _ = _first_on(FaultSpec("v_kmh", 50.0), [0, 1], [20.0, 20.0], [0, 0])   # a run starting beyond it
    assert on == [True, True]


#: a motorway stretch of WLTC 3b (128 -> 130 km/h in 20 s) and, per [fault] key, the table of the
#: baseline run and of the perturbed one
KEY_WINDOW = (1700.0, 1720.0)
KEY_BASE = {"t_s": 5.0}   # the run's time: a segment's starts at 0
PERTURBED = {
    "t_s": {"t_s": 10.0},
    "speed_rpm": {"speed_rpm": 9000.0},
    "v_kmh": {"v_kmh": 128.0},
    "safe_state": {"t_s": 5.0, "safe_state": "freewheel"},
    "duration_s": {"t_s": 5.0, "duration_s": 2.0},
    "i_d_demag": {"t_s": 5.0, "i_d_demag": -321.0},
}


def _toml(table: dict) -> str:
    return "[fault]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in table.items())


@pytest.mark.parametrize("key", sorted(PERTURBED))
def test_every_fault_key_changes_the_run(key, fault_fmus, tmp_path):
    from scenarios.runs.simulate import RunSpec, simulate
    assert set(PERTURBED) == {k.name for k in SCHEMA if k.section == "fault"}
    window = segment(load_cycle("WLTC3b"), *KEY_WINDOW)
    got = []
    for i, table in enumerate((KEY_BASE, PERTURBED[key])):
        d = simulate(window, RunSpec(drive=load_drive(write(tmp_path, _toml(table), f"{i}.toml")), reference=False),
                     fmus=fault_fmus, progress=False).to_dict()
        got.append({k: v for k, v in d.items() if k not in ("wall_s", "real_time_factor", "drive_sha256")})
    changed = sorted(k for k in got[0] if got[0][k] != got[1][k] and k != "fault_trigger")
    assert changed, f"fault.{key} changed nothing"


# -- check limits on the fault's figures ----------------------------------------------------------
def test_judge_passes_and_fails_fault_limits_and_says_why_a_figure_is_missing():
    fig = dict(fault_trigger="fault.v_kmh = 130 km/h", fault_time_s=1720.0, fault_i_peak_A=612.0,
               fault_demag_margin_A=-12.0, fault_T_peak_Nm=95.0, fault_charge_Ah=0.01, fault_energy_Wh=3.0,
               fault_time_to_zero_current_s=None)
    v = {x.limit: x for x in judge("WLTC3b", fig, {"fault_i_peak_A_max": 700.0, "fault_demag_margin_A_min": 0.0,
                                                   "fault_braking_torque_Nm_max": 90.0, "fault_charge_Ah_max": 0.02,
                                                   "fault_time_to_zero_current_s_max": 100.0})}
    assert v["fault_i_peak_A_max"].passed and v["fault_charge_Ah_max"].passed
    assert not v["fault_demag_margin_A_min"].passed and not v["fault_braking_torque_Nm_max"].passed
    assert not v["fault_time_to_zero_current_s_max"].passed
    assert "had not fallen to zero" in v["fault_time_to_zero_current_s_max"].message
    no_trip = judge("UDDS", dict(fault_trigger="fault.v_kmh = 130 km/h"), {"fault_i_peak_A_max": 1e9})[0]
    assert not no_trip.passed and "never reached" in no_trip.message and "130 km/h" in no_trip.message


#: a run that followed its cycle until a trip at 20 s and fell 2.3 km behind after it
FOLLOWED = dict(fault_trigger="fault.t_s = 20 s", fault_time_s=20.0, speed_rmse_mps=12.0, distance_km=0.5,
                cycle_distance_km=2.8, cycle_moving_s=100.0, speed_rmse_before_fault_mps=0.1,
                distance_before_fault_km=0.6, cycle_distance_before_fault_km=0.605, cycle_moving_before_fault_s=20.0)


@pytest.mark.parametrize("change, passed", [
    ({}, {"cycle_speed_rmse_mps_max": True, "cycle_distance_km_min": True}),
    # behind before the trip: 0.5 m/s RMS; 593.8 m, short of 605 m less 2 km/h over 20 s (593.9 m)
    ({"speed_rmse_before_fault_mps": 0.5}, {"cycle_speed_rmse_mps_max": False, "cycle_distance_km_min": True}),
    ({"distance_before_fault_km": 0.5938}, {"cycle_speed_rmse_mps_max": True, "cycle_distance_km_min": False}),
    # a trip at the cycle's start: nothing before it, the speed error undefined (fails)
    ({"fault_time_s": 0.0, "speed_rmse_before_fault_mps": math.nan, "distance_before_fault_km": 0.0,
      "cycle_distance_before_fault_km": 0.0, "cycle_moving_before_fault_s": 0.0},
     {"cycle_speed_rmse_mps_max": False, "cycle_distance_km_min": True}),
    # the before-fault figures missing from a tripped run's summary: never a pass
    ({"distance_before_fault_km": None, "cycle_distance_before_fault_km": None},
     {"cycle_speed_rmse_mps_max": True, "cycle_distance_km_min": False}),
])
def test_a_tripped_run_is_judged_on_the_cycle_before_the_trip(change, passed):
    s = {**FOLLOWED, **change}
    v = {x.limit: x for x in judge("c", s, {})}
    assert set(v) == set(CYCLE_FOLLOWING)
    assert {k: x.passed for k, x in v.items()} == passed
    for x in v.values():
        assert x.key.endswith("_before_fault_mps") or x.key.endswith("_before_fault_km"), x.key
        assert f"until the trip at t = {s['fault_time_s']:g} s" in x.message, x.message
    if s["cycle_distance_before_fault_km"] is not None:   # the cycle's until the trip less 2 km/h over its moving time
        km = s["cycle_distance_before_fault_km"] - 2.0 / 3.6 * s["cycle_moving_before_fault_s"] / 1000.0
        assert v["cycle_distance_km_min"].bound == pytest.approx(max(km, 0.0))
    if math.isnan(v["cycle_speed_rmse_mps_max"].figure):
        assert "no part of it before the trip" in v["cycle_speed_rmse_mps_max"].message


def test_a_run_whose_fault_never_came_is_judged_whole():
    s = {k: v for k, v in FOLLOWED.items() if "before_fault" not in k and k != "fault_time_s"}
    v = {x.limit: x for x in judge("c", s, {})}
    assert [v[k].key for k in CYCLE_FOLLOWING] == [key for key, _ in CYCLE_FOLLOWING.values()]
    assert not any(x.passed for x in v.values()) and not any("until the trip" in x.message for x in v.values())


# -- with IpmsmDrive's fault input ----------------------------------------------------------------
@pytest.fixture(scope="module")
def fault_fmus():
    from fmpy import read_model_description
    drive = fmu_path("IpmsmDrive")
    names = {v.name for v in read_model_description(str(drive)).modelVariables}
    missing = {"fault", "safe_state", "inverter_state", "i_peak", "i_d_demag"} - names
    if missing:
        pytest.skip(f"the built IpmsmDrive has no {', '.join(sorted(missing))} (contract, \"Faults\")")
    return fmu_path("IpmsmController"), fmu_path("IpmsmPlant")


#: a motorway window of WLTC 3b: a flying start at 128.5 km/h, the trip at 130 km/h (t = 1720 s),
#: the cycle's deceleration to a stop at 1795 s
WINDOW = (1700.0, 1800.0)


@pytest.fixture(scope="module")
def trip_run(fault_fmus, tmp_path_factory):
    from scenarios.runs.simulate import RunSpec, simulate
    out = tmp_path_factory.mktemp("trip")
    steps = []
    s = simulate(segment(load_cycle("WLTC3b"), *WINDOW), RunSpec(drive=load_drive(TRIP)), fmus=fault_fmus, out=out,
                 progress=False, observe=steps.append)
    return s, steps, out


def test_the_trip_run_has_the_fault_keys(trip_run):
    s, steps, out = trip_run
    d = json.loads((out / "summary.json").read_text())
    assert d["fault_trigger"] == "fault.v_kmh = 130 km/h" and d["fault_safe_state"] == "by_speed"
    t_trip = next(x.t for x in steps if x.fault) - 0.01
    assert d["fault_time_s"] == pytest.approx(t_trip) and 18.0 < t_trip < 22.0   # a segment's time starts at 0
    assert 130.0 <= d["fault_speed_kmh"] < 130.0 + 3.6 * 0.05   # reached within a step's acceleration
    assert d["fault_speed_rpm"] == pytest.approx(d["fault_speed_kmh"] / 3.6 * 8.19 / 0.306 / RPM)
    assert d["fault_state"] == "asc"   # 130 km/h is 9300 r/min, above the onset: the policy's ASC
    assert d["fault_duration_s"] == pytest.approx(WINDOW[1] - WINDOW[0] - d["fault_time_s"])
    for k in ("fault_i_peak_A", "fault_T_peak_Nm"):
        assert isinstance(d[k], float) and math.isfinite(d[k]), k
    # trip.toml gives no i_d_demag and the FMU's default is 0, no limit: no margin
    assert d["fault_i_d_demag_A"] is None and d["fault_demag_margin_A"] is None
    # the peak is at least every current the steps saw, and the FMU's i_peak
    assert d["fault_i_peak_A"] >= max(math.hypot(x.drive.i_d, x.drive.i_q) for x in steps if x.fault)
    assert d["fault_T_peak_Nm"] == pytest.approx(max(-x.drive.T_shaft for x in steps if x.fault))
    # the car stops at 1795 s: the ASC current falls to zero with the speed
    assert d["fault_time_to_zero_current_s"] is not None
    assert d["fault_time_s"] + d["fault_time_to_zero_current_s"] <= WINDOW[1] - WINDOW[0]
    assert d["undefined"] == [k for k, v in d.items() if v is None]


def test_the_trip_run_has_the_cycle_figures_up_to_the_trip(trip_run):
    """The before-fault figures against the steps before the trip, summed here, and the cycle's
    trace integrated by scipy; the run followed the cycle until 130 km/h: check's cycle-following
    verdicts hold there, and fail on the whole run."""
    from scipy.integrate import quad
    s, steps, _ = trip_run
    k = next(i for i, x in enumerate(steps) if x.fault)
    before = steps[:k]
    assert before and before[-1].t == pytest.approx(s.fault_time_s)
    rmse = math.sqrt(sum((x.v - x.v_ref) ** 2 for x in before) / len(before))
    assert s.speed_rmse_before_fault_mps == pytest.approx(rmse, rel=1e-12)
    v0 = segment(load_cycle("WLTC3b"), *WINDOW).speed_mps[0]
    vs = [v0] + [x.v for x in before]
    assert s.distance_before_fault_km == pytest.approx(sum(0.5 * (a + b) * 0.01 for a, b in zip(vs, vs[1:])) / 1000,
                                                       rel=1e-9)
    cycle = segment(load_cycle("WLTC3b"), *WINDOW)
    t = cycle.time_s
    km, _ = quad(lambda x: float(np.interp(x, t, cycle.speed_mps)), 0.0, s.fault_time_s,
                 points=t[t < s.fault_time_s][1:], epsabs=1e-9, limit=200)
    assert s.cycle_distance_before_fault_km == pytest.approx(km / 1000, rel=1e-9)
    assert s.cycle_moving_before_fault_s == pytest.approx(s.fault_time_s)   # at motorway speed throughout
    assert s.distance_before_fault_km < s.distance_km and s.speed_rmse_before_fault_mps < s.speed_rmse_mps
    v = {x.limit: x for x in judge("WLTC3b", s.to_dict(), {})}
    assert all(x.passed for x in v.values()), [x.message for x in v.values()]
    assert s.speed_rmse_before_fault_mps < CYCLE_SPEED_RMSE_MAX < s.speed_rmse_mps
    whole = {k: x for k, x in s.to_dict().items() if k != "fault_time_s"}   # as if judged whole
    assert not all(x.passed for x in judge("WLTC3b", whole, {}))


def test_after_the_trip_the_driver_gets_no_traction(trip_run):
    s, steps, _ = trip_run
    fault = [x for x in steps if x.fault]
    assert fault and all(x.T_ref == 0.0 for x in fault)
    assert all(x.drive.inverter_state in (1, 2) for x in fault)
    assert max(x.drive.T_shaft for x in fault) <= 1e-6   # braking or nothing
    # the cycle holds 124-131 km/h for 10 s after the trip: the car falls behind
    k = steps.index(fault[0])
    assert steps[k + 1000].v < steps[k].v and steps[k + 1000].v < steps[k + 1000].v_ref - 2.0
    # the friction brakes stop it with the cycle
    assert steps[-1].v == 0.0 and any(x.F_brake > 0.0 for x in fault)


def test_the_energy_balances_close_through_the_fault(trip_run):
    s, steps, _ = trip_run
    # the machine: electric input = shaft + copper + iron (+ magnetic energy: ~0 from rest to rest)
    machine = s.shaft_Wh + s.copper_loss_Wh + s.iron_loss_Wh
    assert abs(s.motor_electric_Wh - machine) <= 1e-3 * (abs(s.shaft_Wh) + s.copper_loss_Wh + s.iron_loss_Wh)
    # the DC link: what the battery gave = drive + inverter loss + auxiliary load; its own balance
    dc = s.motor_electric_Wh + s.inverter_loss_Wh + s.aux_Wh
    assert abs(s.energy_battery_Wh - dc) <= 1e-6 * max(1.0, abs(s.energy_battery_Wh))
    assert abs(s.battery_energy_residual_Wh) <= 1e-6 * max(1.0, abs(s.energy_battery_Wh))
    assert abs(s.heat_balance_residual_Wh) <= 1e-3 * (s.copper_loss_Wh + s.iron_loss_Wh)
    # the fault's own figures against the steps (independently summed) and the FMU's integral E_dc
    fault = [x for x in steps if x.fault]
    E = -sum(x.drive.P_dc for x in fault) * 0.01 / 3600.0
    Q = -sum(x.drive.i_dc for x in fault) * 0.01 / 3600.0
    assert s.fault_energy_Wh == pytest.approx(E, rel=1e-9, abs=1e-12)
    assert s.fault_charge_Ah == pytest.approx(Q, rel=1e-9, abs=1e-12)
    k = steps.index(fault[0])
    E_fmu = -(fault[-1].drive.E_dc - steps[k - 1].drive.E_dc) / 3600.0
    assert E == pytest.approx(E_fmu, rel=1e-6, abs=1e-9)


def test_the_trip_run_writes_its_trace_and_picture(trip_run):
    s, _, out = trip_run
    from scenarios.runs.fault_plots import plot_fault
    with open(out / "fault_trace.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    t = [float(r["time_s"]) for r in rows]
    assert t[0] == pytest.approx(s.fault_time_s - 1.0 + 0.01) and t[-1] == pytest.approx(WINDOW[1] - WINDOW[0])
    assert np.allclose(np.diff(t), 0.01)
    assert {r["fault"] for r in rows[:100]} == {"0"} and rows[100]["fault"] == "1"
    png = plot_fault(out, "trip", json.loads((out / "summary.json").read_text()), s.fault_i_d_demag_A)
    assert png.stat().st_size > 20_000


FAULT_DRIVE = '[fault]\nv_kmh = 100.0\nsafe_state = "{state}"\n{demag}[checks]\ncycles = ["{cycle}"]\n'


def _check(tmp_path, capsys, limits: dict, state: str = "asc", cycle: str = "road.csv",
           demag: str = "i_d_demag = -1000.0\n", build: Path | None = None) -> tuple[int, str]:
    (tmp_path / "road.csv").write_text("time_s,speed_mps\n0,26.0\n3,30.0\n8,30.0\n")   # 94 -> 108 km/h
    (tmp_path / "town.csv").write_text("time_s,speed_mps\n0,0.0\n5,10.0\n8,10.0\n")
    p = write(tmp_path, FAULT_DRIVE.format(state=state, cycle=cycle, demag=demag) + "".join(f"{k} = {v!r}\n"
                                                                              for k, v in limits.items()))
    status = cli.main([*(["--build", str(build)] if build else []), "check", str(p), "--out", str(tmp_path / "out")])
    return status, capsys.readouterr().out + (tmp_path / "out" / "check.md").read_text()


def test_check_gates_on_the_fault_figures(fault_fmus, tmp_path, capsys):
    build = fault_fmus[0].parent.parent   # the build folder of the FMUs under test
    status, text = _check(tmp_path, capsys, build=build, limits={
        "fault_i_peak_A_max": 5000.0, "fault_demag_margin_A_min": 0.0, "fault_time_to_zero_current_s_max": 1e6})
    assert status == 1, text   # ASC at speed: the current does not fall to zero before the run ends
    assert "fault_i_peak_A = " in text and "ok   f/road.csv fault_i_peak_A" in text
    assert "ok   f/road.csv fault_demag_margin_A" in text   # |-1000 A| above an ASC peak near 600 A
    assert "FAIL f/road.csv fault_time_to_zero_current_s" in text and "had not fallen to zero" in text
    status, text = _check(tmp_path, capsys, {"fault_i_peak_A_max": 1.0}, build=build)
    assert status == 1 and "FAIL f/road.csv fault_i_peak_A" in text
    status, text = _check(tmp_path, capsys, {"fault_demag_margin_A_min": 0.0}, demag="i_d_demag = -10.0\n",
                          build=build)
    assert status == 1 and "FAIL f/road.csv fault_demag_margin_A" in text   # 10 A: any ASC current passes it
    status, text = _check(tmp_path, capsys, {"fault_demag_margin_A_min": 0.0}, demag="", build=build)
    assert status == 1 and "set fault.i_d_demag" in text
    status, text = _check(tmp_path, capsys, build=build, limits={
        "fault_i_peak_A_max": 5000.0, "fault_braking_torque_Nm_max": 1000.0, "fault_charge_Ah_max": 1.0,
        "fault_energy_Wh_max": 100.0})
    assert status == 0, text   # the car followed the cycle until the trip: the cycle-following verdicts hold
    for key in ("speed_rmse_before_fault_mps", "distance_before_fault_km"):
        assert f"ok   f/road.csv {key} = " in text, text
    assert text.count("until the trip at t = ") == 2 * 2   # stdout and check.md, each verdict


TRIP_AT = '[fault]\nt_s = {t_s}\n[checks]\ncycles = ["road.csv"]\nfault_i_peak_A_max = 5000.0\n{battery}'


@pytest.mark.parametrize("case, t_s, battery, failed", [
    # a pack that cannot deliver (R0 = 5 Ohm: some 6 kW at most, the road load at 100 km/h more): the car falls behind
    # the cycle's 94 -> 108 km/h before the trip at 5 s
    ("weak pack", 5.0, "[battery]\nR0 = 5.0\n", ("speed_rmse_before_fault_mps", "distance_before_fault_km")),
    # a trip at the cycle's start: nothing followed, nothing to judge
    ("trip at the start", 0.0, "", ("speed_rmse_before_fault_mps",)),
    ("normal pack", 5.0, "", ()),
])
def test_a_car_that_did_not_follow_the_cycle_before_the_trip_fails(fault_fmus, tmp_path, capsys, case, t_s, battery,
                                                                   failed):
    (tmp_path / "road.csv").write_text("time_s,speed_mps\n0,26.0\n3,30.0\n8,30.0\n")
    p = write(tmp_path, TRIP_AT.format(t_s=t_s, battery=battery))
    status = cli.main(["--build", str(fault_fmus[0].parent.parent), "check", str(p), "--out", str(tmp_path / "out")])
    text = capsys.readouterr().out
    assert status == (1 if failed else 0), text
    for key in ("speed_rmse_before_fault_mps", "distance_before_fault_km"):
        state = "FAIL" if key in failed else "ok  "
        assert f"{state} f/road.csv {key} = " in text, text
    assert f"until the trip at t = {t_s:g} s" in text
    if case == "trip at the start":
        assert "no part of it before the trip to judge" in text


def test_a_cycle_that_never_trips_fails_a_fault_limit_clearly(fault_fmus, tmp_path, capsys):
    status, text = _check(tmp_path, capsys, {"fault_i_peak_A_max": 5000.0}, cycle="town.csv",
                          build=fault_fmus[0].parent.parent)
    assert status == 1 and "no fault in this cycle: fault.v_kmh = 100 km/h was never reached" in text
    # judged whole, as a run without a [fault] table
    assert "ok   f/town.csv speed_rmse_mps = " in text and "ok   f/town.csv distance_km = " in text
    assert "before_fault" not in text and "until the trip" not in text


def test_the_backend_without_the_drive_fmu_refuses_a_fault(fault_fmus):
    from scenarios.runs.simulate import RunSpec, simulate
    with pytest.raises(InputError) as e:
        simulate(segment(load_cycle("WLTC3b"), *WINDOW), RunSpec(drive=load_drive(TRIP), backend="fmpy"),
                 fmus=fault_fmus, progress=False)
    assert e.value.key == "--backend"


# -- sweep --fault --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sweep(fault_fmus, tmp_path_factory):
    from scenarios.runs.fault_sweep import FaultSweepSpec, run_fault_sweep
    out = tmp_path_factory.mktemp("sweep_fault")
    s = run_fault_sweep(fault_fmus[0].parent / "IpmsmDrive.fmu", out,
                        FaultSweepSpec(drive=load_drive(), speeds_rpm=(3000.0, 9000.0, 12000.0)), progress=False)
    with open(out / "fault_sweep.csv", newline="") as f:
        rows = [{k: (v if k in ("state", "load", "error") else float(v) if v not in ("True", "False") else v == "True")
                 for k, v in r.items()} for r in csv.DictReader(f)]
    return s, rows, out


def test_sweep_writes_its_files(sweep):
    s, rows, out = sweep
    assert s.failed == [], s.failed   # every point ran: the FMU stepped each state from each operating point
    assert len(rows) == s.points == 3 * 2 * 2
    assert {(r["state"], r["load"]) for r in rows} == {(a, b) for a in ("freewheel", "asc")
                                                       for b in ("full_load", "no_load")}
    d = json.loads((out / "summary.json").read_text())
    assert set(d["envelope"]) == {"freewheel", "asc"} and all(e["all_steady"] for e in d["envelope"].values())
    assert (out / "fault_envelope.png").stat().st_size > 20_000
    assert 3000.0 < d["onset_rpm"] <= 9000.0


def test_freewheeling_below_the_onset_carries_no_current_and_above_charges(sweep):
    _, rows, _ = sweep
    low = next(r for r in rows if r["state"] == "freewheel" and r["load"] == "no_load" and r["speed_rpm"] == 3000.0)
    assert low["I_steady_A"] == 0.0 and low["i_dc_steady_A"] == 0.0 and low["inverter_state"] == 1
    high = next(r for r in rows if r["state"] == "freewheel" and r["load"] == "no_load" and r["speed_rpm"] == 9000.0)
    assert high["i_dc_steady_A"] < -1.0 and high["T_shaft_steady_Nm"] < 0.0
    # the bridge's DC current is (3/pi)|i|, less the diodes' loss (contract, "Faults": i_dc losses included)
    u_dc = high["P_dc_steady_W"] / high["i_dc_steady_A"]
    assert -high["i_dc_steady_A"] == pytest.approx(3.0 / math.pi * high["I_steady_A"] - high["P_inv_steady_W"] / u_dc,
                                                   rel=1e-3)


def test_every_steady_point_balances_its_power(sweep):
    """T_shaft w_m = P_dc - P_inv - P_cu - P_fe in the steady state (no magnetic energy change)."""
    _, rows, _ = sweep
    for r in rows:
        if r["error"]:
            continue   # a point the FMU could not run: test_sweep_writes_its_files fails on it
        w = r["speed_rpm"] * RPM
        rhs = r["P_dc_steady_W"] - r["P_inv_steady_W"] - r["P_cu_steady_W"] - r["P_fe_steady_W"]
        assert r["T_shaft_steady_Nm"] * w == pytest.approx(rhs, rel=2e-3, abs=0.5), r


def test_asc_steady_state_is_the_maps_own(sweep):
    """ASC: u = 0, so in the steady state R i_d = w psi_q(i), R i_q = -w psi_d(i): solved here on the
    flux map by scipy, independently of the plant."""
    from scipy.optimize import fsolve
    _, rows, _ = sweep
    d = load_drive()
    fmap = read_flux_map(d.motor.flux_map)
    p, R = d.motor.pole_pairs, d.motor.R_s

    def residual(i, w):
        psi_d, psi_q = fmap.flux(np.array(i[0]), np.array(i[1]))
        return [R * i[0] - w * float(psi_q), R * i[1] + w * float(psi_d)]

    for r in rows:
        if r["state"] != "asc" or r["load"] != "no_load":
            continue
        w = p * r["speed_rpm"] * RPM
        i = fsolve(residual, [r["i_d_steady_A"], r["i_q_steady_A"]], args=(w,), xtol=1e-12)
        assert np.allclose(residual(i, w), 0.0, atol=1e-9)
        assert r["i_d_steady_A"] == pytest.approx(i[0], rel=1e-4, abs=0.05), r
        assert r["i_q_steady_A"] == pytest.approx(i[1], rel=1e-4, abs=0.05), r
