"""Vehicle-side models (no FMUs): vehicle dynamics, driver and brake blending, battery, drive
cycles. Hand calculations and independent references (scipy ODE solutions, the cycle statistics
in SOURCES.md); the inverter's loss is the FMUs' (test_inverter.py).
Fast: a few seconds in all."""
import math

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from scenarios.vehicle.battery import OCV_CSV, Battery, BatteryParams
from scenarios.vehicle.cycles import cycle_stats, load_cycle, read_cycle_csv, segment
from scenarios.vehicle.driver import Driver, DriverParams, blend, simulate_ideal
from scenarios.vehicle.longitudinal import (
    Vehicle,
    VehicleParams,
    coastdown_speed,
    coastdown_time,
    longitudinal_step,
    motor_speed,
    road_load,
    shaft_torque,
    wheel_force,
)

KMH = 1 / 3.6
VP = VehicleParams()


# -- vehicle --------------------------------------------------------------------------------

def test_road_load_and_equivalent_mass_by_hand():
    v = 100 * KMH
    # 115.16 + 3.4319 * 27.7778 + 0.4329 * 771.605 = 115.16 + 95.331 + 334.028
    assert road_load(v, VP) == pytest.approx(544.519, abs=1e-3)
    # rotor: pi/32 * 7650 * 0.12 * 0.171^4 = 0.077060 kg m^2
    assert VP.J_motor == pytest.approx(0.077060, rel=1e-4)
    # (4 * 0.815 + 0.077060 * 8.19^2) / 0.306^2 = (3.26 + 5.16889) / 0.093636 = 90.02 kg
    assert VP.m_eff == pytest.approx(1758 + 90.02, abs=0.01)
    # 100 km/h: 27.7778 * 8.19 / 0.306 = 743.46 rad/s = 7099.6 r/min
    assert motor_speed(v, VP) == pytest.approx(743.46, abs=0.01)
    assert VP.brake_force_max == pytest.approx(0.8 * 1758 * 9.80665)


def test_driveline_efficiency_direction():
    # motoring: the wheels get 97 % of the shaft power; regenerating: the shaft gets 97 % of the wheels'
    w = motor_speed(20.0, VP)
    for T in (50.0, 200.0):
        assert wheel_force(T, VP) * 20.0 == pytest.approx(0.97 * T * w)
        assert -shaft_torque(-wheel_force(T, VP), VP) * w == pytest.approx(0.97 * wheel_force(T, VP) * 20.0)
        assert wheel_force(-T, VP) * 20.0 * 0.97 == pytest.approx(-T * w)
    for F in (-3000.0, -1.0, 0.0, 1.0, 3000.0):
        assert wheel_force(shaft_torque(F, VP), VP) == pytest.approx(F, abs=1e-12)
    # steady 100 km/h: 544.519 N * 0.306 m / (8.19 * 0.97) = 20.974 N m
    assert shaft_torque(road_load(100 * KMH, VP), VP) == pytest.approx(20.974, abs=1e-3)


def test_steady_speed_force_balance():
    v = 100 * KMH
    veh = Vehicle(VP, v0=v)
    F = wheel_force(shaft_torque(road_load(v, VP), VP), VP)
    for _ in range(1000):
        veh.step(F, 0.0, 0.01)
    assert veh.v == pytest.approx(v, abs=1e-9)
    assert veh.distance == pytest.approx(v * 10.0, rel=1e-9)
    # 1 % more force accelerates at 0.01 * 544.5 / 1848 m/s^2
    veh = Vehicle(VP, v0=v)
    veh.step(1.01 * F, 0.0, 1.0)
    assert veh.v - v == pytest.approx(0.01 * F / VP.m_eff, rel=1e-9)


def test_coastdown_from_100_kmh_against_ode_and_closed_form():
    v0 = 100 * KMH
    # independent reference: scipy's ODE solution of m_eff dv/dt = -(A + B v + C v^2)
    def stop(t, y):
        return y[0]

    stop.terminal = True
    sol = solve_ivp(lambda t, y: [-road_load(y[0], VP) / VP.m_eff], (0, 500), [v0], events=stop,
                    rtol=1e-11, atol=1e-12, dense_output=True, method="DOP853")
    t_stop_ode = sol.t_events[0][0]
    assert coastdown_time(v0, VP) == pytest.approx(t_stop_ode, rel=1e-8)
    t = np.linspace(0, t_stop_ode * 0.999, 50)
    assert np.max(np.abs(coastdown_speed(t, v0, VP) - sol.sol(t)[0])) < 1e-8
    # the model's explicit 10 ms steps
    veh, dt, k = Vehicle(VP, v0=v0), 0.01, 0
    vs = [v0]
    while veh.v > 0.0:
        veh.step(0.0, 0.0, dt)
        vs.append(veh.v)
        k += 1
    tk = dt * np.arange(len(vs))
    assert np.max(np.abs(np.array(vs) - coastdown_speed(tk, v0, VP))) < 2e-3   # O(dt) Euler error
    assert k * dt == pytest.approx(t_stop_ode, abs=0.05)
    # coast-down distance: integral of the ODE solution
    d_ode = quad(lambda s: sol.sol(s)[0], 0, t_stop_ode, limit=200)[0]
    assert veh.distance == pytest.approx(d_ode, rel=1e-3)


def test_standstill_is_static():
    # below the break-away force A the car stays; brakes never push it backwards
    assert longitudinal_step(0.0, 0.9 * VP.road_load_A, 0.0, 0.01, VP) == (0.0, 0.0)
    assert longitudinal_step(0.0, 0.0, 5000.0, 0.01, VP) == (0.0, 0.0)
    v, _ = longitudinal_step(0.0, VP.road_load_A + 1848.0, 0.0, 0.01, VP)
    assert v == pytest.approx(0.01 * 1848.0 / VP.m_eff)
    v, _ = longitudinal_step(0.05, 0.0, 10000.0, 0.01, VP)
    assert v == 0.0
    with pytest.raises(ValueError):
        longitudinal_step(1.0, 0.0, -1.0, 0.01, VP)


# -- driver and blending -----------------------------------------------------------------------

def _track(cycle, driver, plant: VehicleParams, dt=0.01):
    """Closed loop driver -> blend (no motor or battery limits) -> vehicle; speed RMSE in km/h."""
    n = int(round(cycle.duration_s / dt))
    v_ref = cycle.speed_at(dt * np.arange(n + 1)).tolist()
    veh = Vehicle(plant)
    err2 = 0.0
    for k in range(n):
        F = driver.demand(v_ref[k], v_ref[k + 1], veh.v, dt)
        b = blend(F, veh.v, math.inf, math.inf, plant)
        F_w = wheel_force(b.T_ref, plant)
        driver.applied(F_w - b.F_brake)
        veh.step(F_w, b.F_brake, dt)
        err2 += (veh.v - v_ref[k + 1]) ** 2
    return math.sqrt(err2 / n) * 3.6, veh.distance


@pytest.fixture(scope="module")
def wltc():
    return load_cycle("WLTC3b")


def test_driver_tracks_whole_wltc_with_ideal_motor(wltc):
    rmse, dist = _track(wltc, Driver(VP), VP)
    assert rmse < 1e-6       # the feed-forward is the plant's exact inverse
    assert dist == pytest.approx(wltc.distance_m, rel=1e-3)


def test_driver_tracks_wltc_with_model_mismatch(wltc):
    # the car is 10 % heavier, its road load 20 % higher and its gear 2 points worse than
    # the driver's model: the PI has to do the work
    plant = VehicleParams(mass=1.1 * VP.mass, road_load_A=1.2 * VP.road_load_A,
                          road_load_B=1.2 * VP.road_load_B, road_load_C=1.2 * VP.road_load_C,
                          driveline_efficiency=0.95)
    rmse, dist = _track(wltc, Driver(VP), plant)
    assert rmse < 1.0
    assert dist == pytest.approx(wltc.distance_m, rel=5e-3)


def test_tracking_metric_can_fail(wltc):
    # negative control: no feed-forward and a sluggish loop misses the trace by far more than 1 km/h
    seg = segment(wltc, 0.0, 600.0)
    rmse, _ = _track(seg, Driver(VP, DriverParams(bandwidth=0.2, feedforward=False)), VP)
    assert rmse > 1.0


def test_anti_windup_stops_integration_when_short():
    d = Driver(VP, DriverParams(feedforward=False))
    for _ in range(100):
        F = d.demand(20.0, 20.0, 10.0, 0.01)
        d.applied(0.0 * F)           # the motor gives nothing
    assert d.integral == 0.0
    d2 = Driver(VP, DriverParams(feedforward=False))
    for _ in range(100):
        F = d2.demand(20.0, 20.0, 10.0, 0.01)
        d2.applied(F)                # met: integrates
    assert d2.integral == pytest.approx(100 * d2.ki * 10.0 * 0.01)


def test_blend_traction_regen_and_friction():
    v = 20.0
    w = motor_speed(v, VP)
    # traction within reach
    b = blend(2000.0, v, 285.0, 0.0, VP)
    assert b.T_ref == pytest.approx(shaft_torque(2000.0, VP)) and b.F_brake == 0 and b.F_unmet_traction == 0
    # traction beyond reach: clamped, shortfall reported
    b = blend(9000.0, v, 100.0, 0.0, VP)
    assert b.T_ref == 100.0
    assert b.F_unmet_traction == pytest.approx(9000.0 - wheel_force(100.0, VP))
    # gentle braking: all regenerative
    b = blend(-1500.0, v, 285.0, 1e6, VP)
    assert b.T_ref == pytest.approx(shaft_torque(-1500.0, VP)) and b.F_brake == pytest.approx(0, abs=1e-9)
    # hard braking: the motor to T_max, friction the rest
    b = blend(-8000.0, v, 150.0, 1e6, VP)
    assert b.T_ref == -150.0 and b.regen_limit == "motor"
    assert wheel_force(b.T_ref, VP) - b.F_brake == pytest.approx(-8000.0)
    # the battery takes only 10 kW: regen torque 10 kW / w_m
    b = blend(-3000.0, v, 285.0, 10e3, VP)
    assert b.T_ref == pytest.approx(-10e3 / w) and b.regen_limit == "battery"
    assert wheel_force(b.T_ref, VP) - b.F_brake == pytest.approx(-3000.0)
    # standstill: friction holds; beyond the adhesion limit the shortfall is reported
    b = blend(-500.0, 0.0, 285.0, 1e6, VP)
    assert (b.T_ref, b.F_brake) == (0.0, 500.0)
    b = blend(-2 * VP.brake_force_max, v, 0.0, 0.0, VP)
    assert b.F_brake == pytest.approx(VP.brake_force_max) and b.F_unmet_braking == pytest.approx(VP.brake_force_max)


def test_ideal_drive_energy_balance_closes():
    r = simulate_ideal(segment(load_cycle("UDDS"), 0.0, 300.0))
    lhs = r.energy_battery_Wh
    rhs = r.shaft_motoring_Wh + r.shaft_regen_Wh + r.motor_loss_Wh + r.inverter_loss_Wh + r.aux_Wh
    assert lhs == pytest.approx(rhs, rel=1e-9)
    # the wheels' work uses the step's mean speed (it is what changes the kinetic energy), the
    # shaft's the speed held over the step (what the drive sees): they differ by F a dt^2 / 2 a step
    assert r.wheel_traction_Wh == pytest.approx(0.97 * r.shaft_motoring_Wh, rel=1e-3)
    assert r.speed_rmse_kmh < 1e-6


# -- battery ------------------------------------------------------------------------------

def test_ocv_at_the_data_points_and_between():
    data = np.genfromtxt(OCV_CSV, delimiter=",", names=True)
    for fit, col, pack in (("chen2020", "ocv_cell_chen2020_V", "ocv_pack96s_chen2020_V"),
                           ("pybamm_ecm_example", "ocv_cell_pybamm_ecm_example_V", "ocv_pack96s_pybamm_ecm_example_V")):
        b = Battery(BatteryParams(ocv_fit=fit))
        for s, cell, pk in zip(data["soc"], data[col], data[pack]):
            assert b.ocv(s) == pytest.approx(96 * cell, abs=1e-9)
            assert b.ocv(s) == pytest.approx(pk, abs=0.011)   # the file's pack column: both columns rounded
        mids = 0.5 * (data["soc"][1:] + data["soc"][:-1])
        ocv_mid = np.array([b.ocv(s) for s in mids])
        assert np.all(ocv_mid > 96 * data[col][:-1]) and np.all(ocv_mid < 96 * data[col][1:])
    b = Battery()
    assert b.ocv(0.5) == pytest.approx(355.69, abs=0.01)    # 96 x 3.7051 V: the motor's 355 V design point
    assert b.u == b.ocv()
    with pytest.raises(ValueError):
        b.ocv(1.01)
    with pytest.raises(ValueError):
        Battery(BatteryParams(ocv_fit="nope"))


def test_pack_capacity_is_40_kwh():
    p = BatteryParams()
    E = p.capacity_As * Battery(p).ocv_fn.integral(0.0, 1.0) / 3.6e6
    assert E == pytest.approx(39.89, abs=0.01)   # 112.6 Ah x 96 x 3.690 V mean (PCHIP)
    data = np.genfromtxt(OCV_CSV, delimiter=",", names=True)
    E_trapz = p.capacity_As * 96 * np.trapezoid(data["ocv_cell_chen2020_V"], data["soc"]) / 3.6e6
    assert E == pytest.approx(E_trapz, rel=1e-3)
    assert p.u_max == pytest.approx(403.2)


def test_power_demand_solves_the_quadratic():
    b = Battery()
    for P in (50e3, -30e3, 0.0, 1e3):
        r = b.step(P, 0.01)
        assert r.u * r.i == pytest.approx(P, abs=1e-6)
        assert r.P_curtailed == 0.0 and r.P_unmet == 0.0
    b = Battery()
    r = b.step(1e3, 0.01)
    # at rest with u_RC = 0: u = OCV - R_eff i, R_eff ~ R0 + R1 dt / (2 tau)
    assert r.i == pytest.approx(1e3 / 355.69, rel=1e-3)
    r = Battery().step(2e6, 0.01)        # beyond E0^2 / 4 R
    assert r.P_unmet > 1e6 and r.P == pytest.approx(2e6 - r.P_unmet)


def _rc_reference(currents, dt, p: BatteryParams):
    """Independent RC solution: scipy integrates C1 du/dt = i - u/R1 and d(E)/dt = u i
    step by step with the current held (rtol 1e-11)."""
    u, E = 0.0, 0.0
    for i in currents:
        s = solve_ivp(lambda t, y, i=i: [(i - y[0] / p.R1) / p.C1, y[0] * i], (0, dt), [u, E],
                      rtol=1e-11, atol=1e-9, method="DOP853")
        u, E = s.y[0, -1], s.y[1, -1]
    return u, E


def test_battery_energy_conservation():
    p = BatteryParams(soc0=0.6)
    b = Battery(p)
    dt = 1.0     # the step is exact for any dt, so a coarse one makes errors visible
    rng = np.random.default_rng(1)
    powers = np.concatenate([rng.uniform(-60e3, 90e3, 150), np.full(50, -40e3), np.full(50, 80e3), np.zeros(50)])
    rs = [b.step(float(P), dt) for P in powers]
    i = np.array([r.i for r in rs])
    u = np.array([r.u for r in rs])
    E_term = float(np.sum(u * i) * dt)
    assert E_term == pytest.approx(float(np.sum(powers)) * dt, rel=1e-12)
    # chemical energy by quadrature of the OCV between the end SOCs
    soc_end = p.soc0 - np.sum(i) * dt / p.capacity_As
    assert b.soc == pytest.approx(soc_end, abs=1e-12)
    E_ocv = p.capacity_As * quad(lambda s: b.ocv_fn.pchip(s), soc_end, p.soc0, limit=200, epsabs=1e-9)[0]
    E_R0 = p.R0 * float(np.sum(i * i)) * dt
    u_rc_end, E_rc = _rc_reference(i, dt, p)       # integral of u_RC i dt
    assert b.u_rc == pytest.approx(u_rc_end, abs=1e-8)
    assert E_term == pytest.approx(E_ocv - E_R0 - E_rc, rel=1e-7)
    # the model's own counters agree
    assert b.E_ocv == pytest.approx(E_ocv, rel=1e-9)
    assert abs(b.energy_residual()) < 1e-7 * b.E_ocv
    assert b.E_loss_R1 + b.W_C == pytest.approx(E_rc, rel=1e-7)
    assert b.E_loss_R0 == pytest.approx(E_R0, rel=1e-12)


def test_regen_cap_4v2_per_cell():
    p = BatteryParams(soc0=0.97)
    b = Battery(p)
    dt = 0.01
    near = 0
    total_curtailed = 0.0
    for k in range(6000):
        P_dem = -100e3 if k < 4000 else -b.max_charge_power(dt)
        r = b.step(P_dem, dt)
        assert r.u <= p.u_max + 1e-6 and r.u_end <= p.u_max + 1e-6
        assert r.P - r.P_curtailed == pytest.approx(P_dem, abs=1e-6)
        assert r.P_curtailed >= 0.0
        if k >= 4000:
            assert r.P_curtailed == pytest.approx(0.0, abs=1e-6)   # demanding exactly the limit
        near += p.u_max - r.u_end < 1e-3
        total_curtailed += r.P_curtailed * dt
    assert near > 1000                    # the cap is what limits the charge
    assert total_curtailed > 40e3 * 40    # most of the 100 kW was refused for 40 s
    assert b.soc <= 1.0
    assert b.E_curtailed == pytest.approx(total_curtailed)
    # a full battery takes nothing
    full = Battery(BatteryParams(soc0=1.0))
    assert full.max_charge_power(dt) == 0.0
    r = full.step(-5e3, dt)
    assert r.P == 0.0 and r.P_curtailed == pytest.approx(5e3)


# -- cycles --------------------------------------------------------------------------------

# SOURCES.md, "Verified statistics": distance km, duration s, v_max km/h
PUBLISHED = {
    "WLTC3b": (23.2663, 1800, 131.30),
    "UDDS": (11.9902, 1369, 91.25),
    "HWFET": (16.5065, 765, 96.40),
    "US06": (12.8876, 600, 129.23),
    "NEDC": (11.0282, 1180, 120.00),
}


@pytest.mark.parametrize("name", list(PUBLISHED))
def test_cycle_statistics_match_sources(name):
    d_km, T, vmax = PUBLISHED[name]
    c = load_cycle(name.lower())
    t, v = c
    assert c.name == name
    assert t[0] == 0.0 and len(t) == T + 1
    assert c.distance_m / 1000 == pytest.approx(d_km, abs=1e-4)
    assert c.duration_s == T
    s = cycle_stats(c)
    assert s["v_max_mps"] * 3.6 == pytest.approx(vmax, abs=0.01)
    assert s["distance_m"] == c.distance_m


def test_segment_and_user_csv(tmp_path, wltc):
    a, b = segment(wltc, 0.0, 700.5), segment(wltc, 700.5, 1800.0)
    assert a.distance_m + b.distance_m == pytest.approx(wltc.distance_m, rel=1e-12)
    assert b.time_s[0] == 0.0 and b.duration_s == pytest.approx(1099.5)
    f = tmp_path / "mine.csv"
    f.write_text("# my trace\ntime_s,speed_mps\n0,0\n0.5,1.0\n2,3\n")
    c = load_cycle(f)
    assert c.name == "mine" and c.distance_m == pytest.approx(0.25 + 3.0)
    assert c.speed_at(1.25) == pytest.approx(2.0)


@pytest.mark.parametrize("text,msg", [
    ("t,v\n0,0\n1,1\n", "line 1: the header"),
    ("time_s,speed_mps\n0,0\n1,abc\n", "line 3: two numbers"),
    ("time_s,speed_mps\n0,0\n1,1,2\n", "line 3: 2 columns, got 3"),
    ("time_s,speed_mps\n0,0\n1,1\n1,2\n", "line 4: time increasing"),
    ("time_s,speed_mps\n0,0\n1,-1\n", "line 3: a speed >= 0"),
    ("time_s,speed_mps\n0,0\n1,120\n", "km/h or mph"),
    ("time_s,speed_mps\n0,0\n1,nan\n", "NaN"),
    ("time_s,speed_mps\n0,0\n", "at least 2"),
    ("", "empty"),
])
def test_bad_cycle_files(tmp_path, text, msg):
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(ValueError, match=msg):
        read_cycle_csv(f)


def test_unknown_cycle_and_missing_file(tmp_path):
    with pytest.raises(ValueError, match="unknown cycle"):
        load_cycle("JC08")
    with pytest.raises(FileNotFoundError):
        load_cycle(tmp_path / "nope.csv")
    with pytest.raises(ValueError, match="not inside"):
        segment(load_cycle("US06"), 100.0, 700.0)


def test_a_run_that_never_moves_has_no_energy_per_km_and_no_crash(tmp_path):
    """A segment at standstill (0 km): Wh_per_km is null in summary.json (no division by zero)."""
    import json

    from scenarios.runs.simulate import RunSpec, simulate
    from scenarios.vehicle.cycles import Cycle

    still = Cycle("standstill", np.array([0.0, 2.0]), np.array([0.0, 0.0]))
    s = simulate(still, RunSpec(reference=False), out=tmp_path, progress=False)
    assert s.distance_km == 0.0 and s.Wh_per_km is None
    assert json.loads((tmp_path / "summary.json").read_text())["Wh_per_km"] is None
