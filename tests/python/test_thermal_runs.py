"""Whole runs with the machine's thermal network on (docs/thermal.md, "Scenarios"): the heat
balance over a drive cycle and a full-power climb through IpmsmDrive; the run's temperatures
against an independent integration of the network (thermal_reference.py, written from the
source) fed the run's own per-step losses, speed and current, by scipy's solve_ivp; the [thermal]
table's boundary; the scenarios end to end through the CLI; the road grade's physics; the study's
heating condition. Short windows by default, the whole scenarios marked slow."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from thermal_reference import MAGNET, WINDING, Network

from scenarios import __main__ as cli
from scenarios.core.paths import DATA_DIR
from scenarios.drives.description import DRIVES_DIR, DriveDescriptionError, load_drive
from scenarios.maps.flux_map import DEFAULT_MAP
from scenarios.runs.simulate import STUDY_CONDITIONS, Conditions, RunSpec, simulate
from scenarios.vehicle.cycles import load_cycle, repeated, segment
from scenarios.vehicle.longitudinal import G_N, Vehicle, VehicleParams, coastdown_time, grade_force, road_load

THERMAL = DRIVES_DIR / "thermal.toml"
CLIMB = DRIVES_DIR / "thermal_climb.toml"
CLIMB_CYCLE = DATA_DIR / "cycles" / "thermal" / "climb_150kmh.csv"
MOTORWAY = DATA_DIR / "cycles" / "thermal" / "WLTC3b_extra_high.csv"
START = 293.15  # K, where the runs start the network (the default conditions' temperatures)


def thermal_run(cycle, drive_path, fmus, **spec):
    """The run's summary and its vehicle steps."""
    steps = []
    s = simulate(cycle, RunSpec(drive=load_drive(drive_path), reference=False, **spec), fmus=fmus, progress=False,
                 observe=steps.append)
    return s, steps


def independent_temperatures(steps, drive, dt=0.01, theta0=START):
    """The network integrated by solve_ivp from the run's per-step loss powers (the drive's
    E_cu, E_fe increases over each step), held speed and end-of-step current, as the FMU holds its
    inputs: (node temperatures at each step's end (steps x 4), heat into the coolant (J))."""
    net, Tc, Ta = Network(), drive.thermal.T_coolant, drive.thermal.T_ambient
    C, n = net.C(), len(steps)
    E_cu = np.array([s.drive.E_cu for s in steps])
    E_fe = np.array([s.drive.E_fe for s in steps])
    P_cu, P_fe = np.diff(E_cu, prepend=0.0) / dt, np.diff(E_fe, prepend=0.0) / dt
    A, b = np.empty((n, 5, 5)), np.empty((n, 5))
    A[:, 4, :], A[:, :, 4] = 0.0, 0.0
    for k, s in enumerate(steps):
        K, Gb = net.matrices(s.w_m, Tc)
        I_rms = math.sqrt(0.5 * (s.drive.i_d ** 2 + s.drive.i_q ** 2))
        A[k, :4, :4] = -K / C[:, None]
        b[k, :4] = (net.losses(P_cu[k], P_fe[k], s.w_m, I_rms) + Gb @ [Tc, Ta]) / C
        A[k, 4, :4] = Gb[:, 0]          # the fifth state: heat into the coolant
        b[k, 4] = -Gb[:, 0].sum() * Tc

    def rhs(t, y):
        k = min(int(t / dt), n - 1)
        return A[k] @ y + b[k]

    edges = dt * np.arange(n + 1)
    sol = solve_ivp(rhs, (0.0, edges[-1]), [theta0] * 4 + [0.0], t_eval=edges[1:], method="RK45",
                    rtol=1e-9, atol=1e-8, max_step=dt)
    assert sol.success, sol.message
    return sol.y[:4].T, sol.y[4, -1]


def check_whole_run(summary, steps, drive, heated_by: float):
    """The heat balance within 1e-6 of the throughput; the temperatures within 0.01 K of the
    independent integration at every step; the coolant's heat within 1e-5 of the throughput."""
    m = steps[-1].drive
    throughput = m.E_cu + m.E_fe
    assert abs(throughput - m.E_stored - m.E_coolant - m.E_ambient) < 1e-6 * throughput
    assert summary.heat_balance_residual_Wh * 3600.0 == pytest.approx(
        throughput - m.E_stored - m.E_coolant - m.E_ambient, abs=1e-9 * throughput)
    got = np.array([[s.drive.theta_stator_yoke, s.drive.theta_stator_tooth, s.drive.theta_winding,
                     s.drive.theta_magnet] for s in steps])
    ref, E_coolant = independent_temperatures(steps, drive)
    worst = np.max(np.abs(got - ref))
    print(f"\nworst temperature difference {worst:.3g} K over {len(steps)} steps; winding "
          f"{got[-1, WINDING] - START:+.1f} K, magnets {got[-1, MAGNET] - START:+.1f} K")
    assert worst < 0.01, worst
    # the reference's own error (its temperatures are 1e-3 K off after 20 min: RK45 across the
    # steps' jumps) bounds this comparison, not the FMU's (3.4e-6 of the throughput on US06 x 2)
    print(f"heat into the coolant vs the reference: {(m.E_coolant - E_coolant) / throughput:.2g} of the throughput")
    assert abs(m.E_coolant - E_coolant) < 1e-5 * throughput, (m.E_coolant, E_coolant)
    assert got[:, WINDING].max() > START + heated_by  # the run heats the machine: a real test
    assert summary.theta_winding_max_K == pytest.approx(got[:, WINDING].max(), abs=0.0)


def test_a_drive_cycle_through_ipmsmdrive(controller_fmu, plant_fmu):
    """US06's first two minutes with a 65 degC coolant, the default network."""
    s, steps = thermal_run(segment(load_cycle("US06"), 0.0, 120.0), THERMAL, (controller_fmu, plant_fmu))
    check_whole_run(s, steps, load_drive(THERMAL), heated_by=10.0)


def test_a_full_power_climb_through_ipmsmdrive(controller_fmu, plant_fmu):
    """The climb's first two minutes: after the ramp the driver asks for more than the torque
    limit (full power), and the winding heats fast."""
    s, steps = thermal_run(segment(load_cycle(CLIMB_CYCLE), 0.0, 120.0), CLIMB, (controller_fmu, plant_fmu))
    at_limit = [st for st in steps if st.t > 40.0]
    assert all(st.T_ref >= 0.999 * st.drive.T_max for st in at_limit[1:])  # the torque limit, all along
    assert min(st.drive.P_mech for st in at_limit) > 80e3   # W: full power
    check_whole_run(s, steps, load_drive(CLIMB), heated_by=40.0)


@pytest.mark.slow
def test_repeated_us06_and_the_whole_climb(controller_fmu, plant_fmu):
    # the climb heats the winding until the derating holds it (about 159 degC from a 20 degC start)
    for cycle, drive, heated in ((repeated(load_cycle("US06"), 2), THERMAL, 50.0), (load_cycle(CLIMB_CYCLE), CLIMB,
                                                                                     100.0)):
        s, steps = thermal_run(cycle, drive, (controller_fmu, plant_fmu))
        check_whole_run(s, steps, load_drive(drive), heated_by=heated)


# -- off means off, and the [thermal] table's boundary ---------------------------------------------
def test_a_thermal_table_switched_off_is_todays_run(tmp_path, controller_fmu, plant_fmu):
    """thermal_model = false with the network's keys given: the summary and the trace as with no
    [thermal] table (the drive's name and file hash aside)."""
    text = (DRIVES_DIR / "default.toml").read_text().replace('"../../', f'"{DRIVES_DIR.parent.parent}/')
    off = tmp_path / "off.toml"
    off.write_text(text + "\n[thermal]\nthermal_model = false\nT_coolant = 350.0\nC_winding = 100.0\n")
    cycle = segment(load_cycle("US06"), 26.0, 44.0)
    a = simulate(cycle, RunSpec(), out=tmp_path / "a", progress=False).to_dict()
    b = simulate(cycle, RunSpec(drive=load_drive(off)), out=tmp_path / "b", progress=False).to_dict()
    for k in ("wall_s", "real_time_factor", "drive", "drive_sha256"):
        a.pop(k), b.pop(k)
    assert a == b and not a["thermal_network"] and a["theta_winding_max_K"] is None
    assert (tmp_path / "a" / "trace.csv").read_text() == (tmp_path / "b" / "trace.csv").read_text()


@pytest.mark.parametrize("line, key", [("C_winding = -1.0", "thermal.C_winding"),
                                       ("thermal_model = 1", "thermal.thermal_model"),
                                       ("T_coolant = 10.0", "thermal.T_coolant"),
                                       ("k_fe_yoke = 1.5", "thermal.k_fe_yoke"),
                                       ("R_coolant_yok = 0.02", "thermal.R_coolant_yok")])
def test_a_bad_thermal_key_exits_2_naming_file_and_key(tmp_path, capsys, line, key):
    bad = tmp_path / "bad.toml"
    on = "" if line.startswith("thermal_model") else "thermal_model = true\n"
    bad.write_text(f'[motor]\nflux_map = "{DEFAULT_MAP}"\n[thermal]\n{on}{line}\n')
    with pytest.raises(DriveDescriptionError) as e:
        load_drive(bad)
    assert e.value.key == key
    assert cli.main(["run", "US06", "--drive", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and key in err and not (tmp_path / "o").exists()


def test_the_defaults_are_the_fmus():
    """No [thermal] key given: the FMU's start values, read from its model description."""
    from scenarios.core.fmu_ranges import fmu_starts
    d = load_drive(None)
    assert not d.thermal.on and d.thermal.fmu_params() == {}
    assert all(d.thermal.values[k] == fmu_starts()[k] for k in d.thermal.values)
    assert d.thermal.values["C_winding"] == Network().C_winding  # the source's value, through the FMU


def test_the_fmpy_backend_refuses_the_network(tmp_path, capsys):
    assert cli.main(["run", "US06", "--drive", str(THERMAL), "--backend", "fmpy", "--out", str(tmp_path / "o")]) == 2
    assert "--backend" in capsys.readouterr().err


# -- the scenarios end to end ----------------------------------------------------------------------
def test_run_with_a_thermal_table_shows_temperatures_and_derating(tmp_path, capsys):
    """`run CYCLE --repeat 2 --drive thermal.toml`: thermal.png beside run.png, the trace's node
    temperatures and derating, the summary's figures."""
    short = tmp_path / "us06_start.csv"
    c = segment(load_cycle("US06"), 0.0, 42.0)  # to US06's first stop
    short.write_text("time_s,speed_mps\n" + "".join(f"{float(t)!r},{float(v)!r}\n"
                                                     for t, v in zip(c.time_s, c.speed_mps)))
    out = tmp_path / "run"
    assert cli.main(["run", str(short), "--repeat", "2", "--drive", str(THERMAL), "--out", str(out)]) == 0
    assert "thermal.png" in capsys.readouterr().out
    assert (out / "thermal.png").stat().st_size > 10_000 and (out / "run.png").exists()
    s = json.loads((out / "summary.json").read_text())
    assert s["thermal_network"] and s["cycle"] == "us06_start x2"
    assert s["theta_winding_max_K"] > START + 5.0 and s["theta_magnet_max_K"] > START
    assert abs(s["heat_balance_residual_Wh"]) < 1e-6 * (s["copper_loss_Wh"] + s["iron_loss_Wh"])
    assert s["time_derated_s"] >= 0.0 and 0.0 <= s["derating_min"] <= 1.0
    header = (out / "trace.csv").read_text().splitlines()[0].split(",")
    for col in ("theta_winding_K", "theta_magnet_K", "theta_stator_yoke_K", "theta_stator_tooth_K", "P_coolant_W",
                "derating", "P_demand_W", "P_wheel_W"):
        assert col in header


@pytest.mark.slow
@pytest.mark.parametrize("args", [["US06", "--repeat", "3", "--drive", str(THERMAL)],
                                  [str(MOTORWAY), "--repeat", "4", "--drive", str(THERMAL)],
                                  [str(CLIMB_CYCLE), "--drive", str(CLIMB)]], ids=["us06x3", "motorway", "climb"])
def test_the_thermal_scenarios(tmp_path, capsys, args):
    out = tmp_path / "run"
    assert cli.main(["run", *args, "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["thermal_network"] and (out / "thermal.png").exists()
    assert abs(s["heat_balance_residual_Wh"]) < 1e-6 * (s["copper_loss_Wh"] + s["iron_loss_Wh"])
    assert s["theta_winding_max_K"] > s["theta_winding_end_K"] - 1e-9


def test_repeat_is_checked(tmp_path, capsys):
    for n in ("0", "101"):
        assert cli.main(["run", "US06", "--repeat", n, "--out", str(tmp_path / "o")]) == 2
        assert "--repeat" in capsys.readouterr().err
    ramp = tmp_path / "ramp.csv"
    ramp.write_text("time_s,speed_mps\n0,0\n1,2\n")  # ends at another speed: its copies would not join
    assert cli.main(["run", str(ramp), "--repeat", "2", "--out", str(tmp_path / "o")]) == 2


def test_repeated_cycles_join():
    c = load_cycle("US06")
    r = repeated(c, 3)
    assert r.duration_s == 3 * c.duration_s and r.distance_m == pytest.approx(3 * c.distance_m, rel=1e-12)
    assert np.all(np.diff(r.time_s) > 0) and r.speed_at(c.duration_s + 5.0) == c.speed_at(5.0)
    xh = load_cycle(MOTORWAY)   # GTR 15's Extra High 3 phase: 8.254 km in 323 s
    assert xh.duration_s == 323.0 and xh.distance_m / 1e3 == pytest.approx(8.254, abs=5e-4)


# -- the road grade -------------------------------------------------------------------------------
def test_grade_force_is_the_weights_component_along_the_road():
    p = VehicleParams(grade=0.10)
    theta = math.atan(0.10)
    assert grade_force(p) == pytest.approx(p.mass * G_N * math.sin(theta), rel=1e-14)
    assert grade_force(VehicleParams()) == 0.0


def test_coasting_uphill_against_solve_ivp():
    """A car coasting up a 6 % grade from 100 km/h: the explicit steps against a tight solve_ivp of
    m_eff dv/dt = -(A + B v + C v^2) - m g sin(atan(grade)), to the stop."""
    p = VehicleParams(grade=0.06)
    v0, dt = 100 / 3.6, 1e-3
    car = Vehicle(p, v0)
    t = 0.0
    while car.v > 0.0:
        car.step(0.0, 0.0, dt)
        t += dt
    stop = lambda t, y: y[0]  # noqa: E731
    stop.terminal = True
    sol = solve_ivp(lambda t, y: [-(road_load(y[0], p) + grade_force(p)) / p.m_eff], (0, 200), [v0], events=stop,
                    rtol=1e-12, atol=1e-12, dense_output=True)
    t_stop = sol.t_events[0][0]
    assert t == pytest.approx(t_stop, abs=2 * dt)
    assert t_stop < 0.5 * coastdown_time(v0, VehicleParams())  # the grade stops it far sooner than the flat road
    assert car.distance == pytest.approx(solve_ivp(lambda t, y: [sol.sol(t)[0]], (0, t_stop), [0.0],
                                                   rtol=1e-10).y[0, -1], rel=1e-3)


def test_a_grade_costs_energy(tmp_path, controller_fmu, plant_fmu):
    """The same window on a 5 % grade: the potential energy m g h comes from the battery."""
    cycle = segment(load_cycle("US06"), 100.0, 130.0)
    flat = simulate(cycle, RunSpec(reference=False), fmus=(controller_fmu, plant_fmu), progress=False)
    hill = tmp_path / "hill.toml"
    hill.write_text((DRIVES_DIR / "default.toml").read_text().replace('"../../', f'"{DRIVES_DIR.parent.parent}/') +
                    "\n[vehicle]\ngrade = 0.05\n")
    up = simulate(cycle, RunSpec(drive=load_drive(hill), reference=False), fmus=(controller_fmu, plant_fmu),
                  progress=False)
    d = load_drive(hill)
    rise = up.distance_km * 1e3 * 0.05 / math.sqrt(1 + 0.05 ** 2)
    m_g_h_Wh = d.vehicle.mass * G_N * rise / 3600.0
    extra = up.shaft_Wh - flat.shaft_Wh
    assert 0.9 * m_g_h_Wh < extra < 1.2 * m_g_h_Wh, (extra, m_g_h_Wh)


# -- the study's heating condition -----------------------------------------------------------------
def test_the_study_has_the_heating_condition():
    from scenarios.study.spec import Run, parse
    heating = next(c for c in STUDY_CONDITIONS if c.thermal)
    assert heating.T_magnet == START and heating.T_winding == START
    assert Run.of_conditions(heating).conditions() == heating   # the study's column and back
    assert Run(thermal_model=0).conditions().thermal is False
    runs = parse({"study": {"thermal_models": [0, 1], "cycles": "UDDS"}}).runs
    assert [r.thermal_model for r in runs] == [0, 1]
    assert Conditions().thermal is None  # the drive's [thermal] decides


def test_the_heating_condition_runs_the_network_and_reports_it(controller_fmu, plant_fmu):
    """The study's heating condition on the default drive (no [thermal] table): the network on
    from a cold start, and the compare report's table of its temperatures."""
    from scenarios.study.compare import StudyRun, _thermal_lines
    heating = next(c for c in STUDY_CONDITIONS if c.thermal)
    s = simulate(segment(load_cycle("US06"), 0.0, 30.0), RunSpec(conditions=heating),
                 fmus=(controller_fmu, plant_fmu), progress=False)
    assert s.thermal_network and s.conditions["thermal"] is True
    assert START < s.theta_winding_max_K < START + 30.0 and s.copper_loss_optimal_Wh > 0.0
    lines = _thermal_lines([StudyRun("Ferrari, recursion 2 (exact)", "run", s)])
    assert "from 20 °C" in lines[0]
    assert f"{s.theta_magnet_max_K - 273.15:.1f} / {s.theta_magnet_end_K - 273.15:.1f}" in lines[-2]
    off = simulate(segment(load_cycle("US06"), 0.0, 30.0), RunSpec(), fmus=(controller_fmu, plant_fmu),
                   progress=False)
    assert _thermal_lines([StudyRun("Ferrari, recursion 2 (exact)", "run", off)]) == []


def test_the_climb_is_derated_below_the_windings_maximum(controller_fmu, plant_fmu):
    """The climb's first 5 minutes with the controller's derating (an IpmsmDrive that has it): the
    winding reaches the derating band and stays below its maximum; the summary counts the time."""
    from fmpy import read_model_description
    names = {v.name for v in read_model_description(str(controller_fmu.parent / "IpmsmDrive.fmu")).modelVariables}
    if "derating" not in names:
        pytest.skip("this build's IpmsmDrive has no derating")
    drive = load_drive(CLIMB)
    T_max, margin = drive.thermal.values["T_winding_max"], drive.thermal.values["derating_margin"]
    s, steps = thermal_run(segment(load_cycle(CLIMB_CYCLE), 0.0, 300.0), CLIMB, (controller_fmu, plant_fmu))
    derated = [st for st in steps if st.drive.derating < 1.0]
    assert derated and s.time_derated_s == pytest.approx(0.01 * len(derated), abs=1e-6)
    assert s.theta_winding_max_K > T_max - margin          # it got there
    assert s.theta_winding_max_K < T_max                   # and no further
    assert s.derating_min == min(st.drive.derating for st in steps) < 1.0
