"""IpmsmPlant with its thermal network (thermal_model, docs/thermal.md): off, the network is
disconnected (no output moves with its inputs or parameters, the temperatures are the inputs);
on, the heat balance closes on the plant's own loss integrals, the temperatures are the
network's (build/bin/thermal_trace fed the plant's step losses: the same to 1e-9 K), R_s and the
magnet flux follow them, FMU states restore them, bad network parameters are refused."""
import math
import subprocess

import numpy as np
import pytest

from scenarios.core import paths

from fmi2_raw import OK, WARNING, refused

H = 1e-4
THERMAL_OUTPUTS = ("theta_winding", "theta_magnet", "theta_stator_yoke", "theta_stator_tooth", "P_coolant",
                   "E_coolant", "E_ambient", "E_stored")


@pytest.fixture
def plant(fmu_instances):
    return lambda name="plant": fmu_instances("IpmsmPlant", name, logging_on=True)


def drive(p, n, k0=0, w_m=900.0, load=1.0):
    """n steps of a voltage pattern around the back-EMF (load scales the q-voltage's excess); the
    plant's outputs and, per step, what the thermal network needs."""
    rows = []
    for k in range(k0, k0 + n):
        p.set(w_m=w_m, u_d=-10.0 if (k // 20) % 2 == 0 else -25.0,
              u_q=load * (8.0 if (k // 20) % 2 == 0 else -4.0) + 0.312 * w_m)
        assert p.step(H) in (OK, WARNING), p.log.text()
        rows.append(p.outputs())
    return rows


def test_off_the_network_is_disconnected(plant):
    """thermal_model false: T_coolant, T_ambient and the network's parameters move no output bit;
    the temperature outputs are the inputs and no heat flows."""
    a, b = plant("a"), plant("b")
    a.init(T_winding=330.0, T_magnet=350.0)
    b.init(T_winding=330.0, T_magnet=350.0, T_coolant=250.0, T_ambient=400.0, C_winding=1.0, R_yoke_winding=9.0,
           k_fe_yoke=0.1, thermal_model=False)
    b.set(T_coolant=390.0)
    assert drive(a, 200) == drive(b, 200)
    assert b.get("theta_winding", "theta_magnet", "theta_stator_yoke") == [330.0, 350.0, 330.0]
    assert b.get("P_coolant", "E_coolant", "E_ambient", "E_stored") == [0.0, 0.0, 0.0, 0.0]


def full_load_stretch(p, T_c, T_a):
    """A speed ramp at full load, 3000 steps: per step (h, E_cu and E_fe of the step, w_m, I_rms,
    the boundary temperatures), the rows thermal_trace reads."""
    steps, prev = [], p.get("E_cu", "E_fe")
    for k in range(3000):
        w_m = 600.0 + 0.2 * k
        p.set(w_m=w_m, u_d=-60.0, u_q=0.312 * w_m + 40.0)
        assert p.step(H) in (OK, WARNING), p.log.text()
        E = p.get("E_cu", "E_fe")
        i_d, i_q = p.get("i_d", "i_q")
        steps.append((H, E[0] - prev[0], E[1] - prev[1], w_m, np.sqrt(0.5 * (i_d**2 + i_q**2)), T_c, T_a))
        prev = E
    return steps


def test_on_heat_balance_and_the_network_fed_the_plants_losses(plant):
    """A full-load stretch: E_cu + E_fe = E_stored + E_coolant + E_ambient within 1e-6 of the
    throughput; thermal_trace fed the plant's step losses, speed, RMS current and boundary
    temperatures gives the plant's node temperatures within 1e-9 K."""
    p = plant()
    T_c, T_a = 318.15, 303.15
    p.init(thermal_model=True, T_winding=310.0, T_magnet=320.0, T_coolant=T_c, T_ambient=T_a)
    full_load_stretch(p, T_c, T_a)
    E_cu, E_fe, E_st, E_c, E_a = p.get("E_cu", "E_fe", "E_stored", "E_coolant", "E_ambient")
    assert E_cu + E_fe > 100.0  # heat flowed
    assert abs(E_cu + E_fe - E_st - E_c - E_a) < 1e-6 * (E_cu + E_fe)
    theta = p.get("theta_stator_yoke", "theta_stator_tooth", "theta_winding", "theta_magnet")

    # the initial temperatures per node: thermal_trace starts all at one, so start it at the
    # winding's and compare the rises of a run that starts the plant there too
    q = plant("uniform")
    q.init(thermal_model=True, T_winding=310.0, T_magnet=310.0, T_coolant=T_c, T_ambient=T_a)
    steps = full_load_stretch(q, T_c, T_a)
    text = "".join(",".join(repr(float(x)) for x in r) + "\n" for r in steps)
    trace = subprocess.run([str(paths.BUILD_DIR / "bin" / "thermal_trace"), "310.0"], input=text,
                           capture_output=True, text=True, check=True).stdout.splitlines()
    ref = np.array([float(x) for x in trace[-1].split(",")[:4]])
    got = np.array(q.get("theta_stator_yoke", "theta_stator_tooth", "theta_winding", "theta_magnet"))
    assert np.max(np.abs(got - ref)) < 1e-9, got - ref
    assert theta[2] > 310.0  # the winding heated


def test_on_R_s_and_the_magnet_flux_follow_the_network(plant):
    p = plant()
    p.init(thermal_model=True, T_winding=300.0, T_magnet=300.0, T_coolant=300.0, T_ambient=300.0, C_winding=5.0,
           C_magnet=5.0)  # light nodes: they heat visibly within a few hundred steps
    R_s, alpha, T_ref, k_psi, T_m_ref = p.get("R_s", "alpha_cu", "T_winding_ref", "k_psi_T", "T_magnet_ref")
    psi_m0 = p.get("psi_m_T") / (1.0 + k_psi * (300.0 - T_m_ref))
    theta_w, theta_m = p.get("theta_winding", "theta_magnet")
    for _ in range(400):
        p.set(w_m=1000.0, u_d=-80.0, u_q=0.312 * 1000.0 + 60.0, T_winding=200.0, T_magnet=200.0)  # inputs unused
        assert p.step(H) in (OK, WARNING), p.log.text()
        # the step ran at the network's temperatures of its start
        assert p.get("R_s_T") == pytest.approx(R_s * (1.0 + alpha * (theta_w - T_ref)), rel=1e-14)
        assert p.get("psi_m_T") == pytest.approx(psi_m0 * (1.0 + k_psi * (theta_m - T_m_ref)), rel=1e-12)
        theta_w, theta_m = p.get("theta_winding", "theta_magnet")
    assert theta_w > 301.0 and theta_m > 300.0


def test_on_fmu_state_restores_the_network(plant):
    p = plant()
    p.init(thermal_model=True, T_winding=330.0, T_magnet=340.0, T_coolant=310.0)
    drive(p, 30)
    s = p.get_state()
    data = p.serialize(s)
    t = p.t
    a = drive(p, 50, k0=30)
    assert p.set_state(s) == OK
    p.t = t
    assert drive(p, 50, k0=30) == a
    q = plant("fresh")  # not initialised; the same fixed parameters
    assert q.setup() == OK
    q.set(thermal_model=True)
    status, s2 = q.deserialize_status(data)
    assert status == OK, q.log.text()
    assert q.set_state(s2) == OK
    q.t = t
    assert q.get("thermal_model") is True
    assert drive(q, 50, k0=30) == a


def test_bad_network_parameters_are_refused(plant):
    p = plant()
    assert p.setup() == OK and p.enter() == OK
    refused(p, p.set_status, "C_winding", -1.0, match="C_winding")
    p.set(thermal_model=True, R_magnet_coolant_nc=-2.0)  # the bilinear fit negative at a corner
    text = refused(p, p.exit, match="R_magnet_coolant")
    assert "thermal network" in text


# --- IpmsmDrive: the plant's network, advanced once per communication step ----------------------

@pytest.fixture
def drives(fmu_instances):
    return lambda name="drive": fmu_instances("IpmsmDrive", name, logging_on=True)


def drive_cycle(d, n, dt=1e-3):
    """n drive steps of dt: a torque ramp up and down at a rising speed; per step what the
    thermal network needs (h, E_cu, E_fe increments, w_m, I_rms at the end)."""
    steps, prev = [], d.get("E_cu", "E_fe")
    for k in range(n):
        w_m = 200.0 + 0.4 * k
        d.set(T_ref=150.0 * math.sin(math.pi * k / n), w_m=w_m)
        assert d.step(dt) in (OK, WARNING), d.log.text()
        E = d.get("E_cu", "E_fe")
        i_d, i_q = d.get("i_d", "i_q")
        steps.append((dt, E[0] - prev[0], E[1] - prev[1], w_m, math.sqrt(0.5 * (i_d**2 + i_q**2))))
        prev = E
    return steps


def test_drive_off_outputs_the_inputs(drives):
    d = drives()
    d.init(T_winding=330.0, T_magnet=350.0, u_dc=355.0, T_coolant=250.0)
    drive_cycle(d, 20)
    assert d.get("theta_winding", "theta_magnet") == [330.0, 350.0]
    assert d.get("P_coolant", "E_coolant", "E_ambient", "E_stored") == [0.0, 0.0, 0.0, 0.0]


def test_drive_on_heat_balance_and_the_network_fed_the_drives_losses(drives):
    d = drives()
    T_c, T_a = 318.15, 303.15
    d.init(thermal_model=True, T_winding=310.0, T_magnet=310.0, u_dc=355.0, T_coolant=T_c, T_ambient=T_a,
           C_winding=50.0)  # a light winding: it heats visibly in 0.3 s
    steps = drive_cycle(d, 300)
    E_cu, E_fe, E_st, E_c, E_a = d.get("E_cu", "E_fe", "E_stored", "E_coolant", "E_ambient")
    assert E_cu + E_fe > 50.0
    assert abs(E_cu + E_fe - E_st - E_c - E_a) < 1e-6 * (E_cu + E_fe)
    text = "".join(",".join(repr(float(x)) for x in (*r, T_c, T_a)) + "\n" for r in steps)
    trace = subprocess.run([str(paths.BUILD_DIR / "bin" / "thermal_trace"), "310.0", "C_winding=50.0"], input=text,
                           capture_output=True, text=True, check=True).stdout.splitlines()
    ref = np.array([float(x) for x in trace[-1].split(",")[:4]])
    got = np.array(d.get("theta_stator_yoke", "theta_stator_tooth", "theta_winding", "theta_magnet"))
    assert np.max(np.abs(got - ref)) < 1e-9, got - ref
    assert got[2] > 311.0
