"""The IpmsmPlant's inverter states (docs/spec/INTERFACE.md, "Faults"; docs/spec/MATH.md, "The
inverter's safe states") against solutions written here, independently of the FMU:

1. ASC on a linear map: the currents against the closed form of the linear dq equations with
   u = 0 (scipy.linalg.expm), 1e-6 of the peak; the steady state
   i_d = -w^2 L_q psi_m / (R^2 + w^2 L_d L_q), i_q = -w R psi_m / (R^2 + w^2 L_d L_q).
2. ASC on saturated maps (the default map, the measured Baldor map): the steady state against
   scipy's fsolve on the map's interpolant made here (scipy's interpolating bicubic spline of the
   CSV, the FMU's not-a-knot spline).
3. Freewheeling at the fundamental frequency, u = -(2 u_dc/pi) i/|i| while the bridge conducts:
   below the onset |w| |psi_0| = 2 u_dc/pi the current reaches zero and the bridge blocks once
   (no chattering), and from zero none is created; above it, conduction starts once and the
   steady state is fsolve's of -k i/|i| - R i + w J psi(i) = 0, 1e-6; power flows out of the
   machine (P_elec < 0, i_dc < 0, braking torque).
4. Energy over a trip in each state: E_elec = E_cu + E_mech + E_fe + Delta W, the magnetic
   energy Delta W = 1.5 int i . dpsi computed here, 1e-6 of the shaft energy.
5. inverter_state outside 0..2 refused with fmi2Error, the instance usable after; FMU states
   carry the bridge's blocking; inverter_state = 0 bit for bit as the FMU before the faults
   (the baseline FMU of the session, where present).
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp
from scipy.interpolate import RectBivariateSpline
from scipy.optimize import fsolve

from scenarios.cosim.fmu import Fmu
from scenarios.maps.flux_map import linear_flux_map, write_flux_map

import fmi2_raw as raw

LIN = dict(L_d=0.25e-3, L_q=0.6e-3, psi_m=0.08)
R_LIN = 0.05
P = 4
U_DC = 355.0
K_BRIDGE = 2 * U_DC / math.pi
TIGHT = dict(rtol=1e-10, atol=1e-12)
NO_FE = dict(fe_k_h=0.0, fe_k_e=0.0)
BASELINE = Path(os.environ.get("IPMSM_BASELINE_FMU_DIR", "/work/coord/baseline_fmu"))


@pytest.fixture(scope="module")
def linear_map(tmp_path_factory):
    path = tmp_path_factory.mktemp("linear") / "linear.csv"
    write_flux_map(path, linear_flux_map(LIN["L_d"], LIN["L_q"], LIN["psi_m"], 1000.0, 21))
    return path


class MapSpline:
    """psi(i) of a contract CSV: scipy's interpolating bicubic spline (written here, not the FMU's)."""

    def __init__(self, path):
        rows = np.loadtxt(path, delimiter=",", comments="#", skiprows=0, dtype=str)
        head = [r for r in rows if not r[0].startswith("i_d")]
        a = np.array(head, dtype=float)
        self.i_d, self.i_q = np.unique(a[:, 0]), np.unique(a[:, 1])
        pd = np.full((len(self.i_d), len(self.i_q)), np.nan)
        pq = pd.copy()
        for idd, iq, d, q in a:
            pd[np.searchsorted(self.i_d, idd), np.searchsorted(self.i_q, iq)] = d
            pq[np.searchsorted(self.i_d, idd), np.searchsorted(self.i_q, iq)] = q
        self.sd = RectBivariateSpline(self.i_d, self.i_q, pd, kx=3, ky=3, s=0)
        self.sq = RectBivariateSpline(self.i_d, self.i_q, pq, kx=3, ky=3, s=0)

    def psi(self, i):
        return np.array([self.sd.ev(i[0], i[1]), self.sq.ev(i[0], i[1])])

    def current(self, psi, guess):
        return fsolve(lambda i: self.psi(i) - psi, guess, xtol=1e-13)


def map_path(name, default_map_path, measured_map_path):
    return {"default": (default_map_path, 4, 0.012), "baldor": (measured_map_path, 2, 0.63)}[name]


def run(f, state, n, h, **inputs):
    """n steps of h in inverter_state `state`; rows of (i_d, i_q, psi_d, psi_q)."""
    f.set(inverter_state=state, **inputs)
    rows = []
    for _ in range(n):
        f.step(f.t, h)
        rows.append(f.get("i_d", "i_q", "psi_d", "psi_q"))
    return np.array(rows)


# --- 1. ASC on a linear map -------------------------------------------------------------------------

@pytest.mark.parametrize("w_m", [300.0, 1256.6])
def test_asc_linear_closed_form(plant_fmu, linear_map, w_m):
    """A motoring current, then the short circuit: every step against expm, then the steady state."""
    L_d, L_q, psi_m, R = LIN["L_d"], LIN["L_q"], LIN["psi_m"], R_LIN
    om = P * w_m
    A = np.array([[-R / L_d, om], [-om, -R / L_q]])
    h = 1e-4
    with Fmu(plant_fmu, flux_map=str(linear_map), R_s=R, w_m=w_m, i_d_start=-150.0, i_q_start=250.0,
             **NO_FE, **TIGHT) as f:
        psi0 = np.array(f.get("psi_d", "psi_q"))
        got = run(f, 2, 200, h)
        # u = 0, x = psi - (psi_m, 0) = (L_d i_d, L_q i_q): dx/dt = A x + (0, -om psi_m)
        E = scipy.linalg.expm(A * h)
        x_ss = -np.linalg.solve(A, [0.0, -om * psi_m])
        x = np.array([psi0[0] - psi_m, psi0[1]])
        exact = []
        for _ in range(200):
            x = x_ss + E @ (x - x_ss)
            exact.append((x[0] / L_d, x[1] / L_q))
        exact = np.array(exact)
        peak = np.abs(exact).max()
        err = np.abs(got[:, :2] - exact).max() / peak
        print(f"ASC w_m {w_m}: max current error {err:.2e} of the peak {peak:.0f} A")
        assert peak > 200 and err < 1e-6
        run(f, 2, 600, 1e-3)  # settle (decay rate R / L: 0.6 s is > 30 time constants)
        den = R**2 + om**2 * L_d * L_q
        ss = np.array([-om**2 * L_q * psi_m / den, -om * R * psi_m / den])
        i = np.array(f.get("i_d", "i_q"))
        print(f"ASC w_m {w_m}: steady state {i} A, closed form {ss} A")
        assert np.abs(i - ss).max() < 1e-6 * np.abs(ss).max()
        assert f.get("P_elec") == 0.0 and f.get("P_inv") == 0.0 and f.get("i_dc") == 0.0
        assert f.get("T_e") * w_m < 0  # braking


# --- 2. ASC on saturated maps -------------------------------------------------------------------------

@pytest.mark.parametrize("name,w_m", [("default", 400.0), ("default", 700.0), ("default", 1200.0)])
def test_asc_saturated_steady_state(plant_fmu, default_map_path, measured_map_path, name, w_m):
    path, p, R = map_path(name, default_map_path, measured_map_path)
    spline = MapSpline(path)
    om = p * w_m

    def residual(i):
        psi = spline.psi(i)
        return [-R * i[0] + om * psi[1], -R * i[1] - om * psi[0]]

    psi_m = float(spline.sd.ev(0.0, 0.0))
    L_d = float(spline.sd.ev(0.0, 0.0, dx=1))
    starts = [(-psi_m / L_d, 0.0)] + [(d, q) for d in np.linspace(spline.i_d[0], 0, 5) for q in (-0.2, 0.0, 0.2)]
    ss = min((fsolve(residual, g, xtol=1e-14) for g in starts), key=lambda i: np.abs(residual(i)).max())
    assert np.abs(residual(ss)).max() < 1e-9
    with Fmu(plant_fmu, flux_map=str(path), pole_pairs=p, R_s=R, w_m=w_m, **NO_FE, **TIGHT) as f:
        run(f, 2, 3000, 1e-3)
        i = np.array(f.get("i_d", "i_q"))
    err = np.abs(i - ss).max() / np.abs(ss).max()
    print(f"ASC {name} w_m {w_m}: steady state {i} A, fsolve on the map {ss} A, error {err:.1e}")
    assert err < 1e-6


def current_trajectory(spline, R, om, i0, ts, k=0.0):
    """The currents, L(i) di/dt = u(i) - R i + om J psi(i), L = dpsi/di of the map's spline, with the short
    circuit's u = 0 (k = 0) or the conducting bridge's u = -k i/|i|: scipy's DOP853 at rtol 1e-11
    (independent of the plant's flux states, its linearised steps and CVODE)."""

    def f(_, i):
        ps = spline.psi(i)
        u = -k * np.asarray(i) / math.hypot(i[0], i[1]) if k else np.zeros(2)
        rhs = [u[0] - R * i[0] + om * ps[1], u[1] - R * i[1] - om * ps[0]]
        L = [[spline.sd.ev(i[0], i[1], dx=1), spline.sd.ev(i[0], i[1], dy=1)],
             [spline.sq.ev(i[0], i[1], dx=1), spline.sq.ev(i[0], i[1], dy=1)]]
        return np.linalg.solve(L, rhs)

    sol = solve_ivp(f, (0.0, ts[-1]), list(i0), method="DOP853", rtol=1e-11, atol=1e-8, t_eval=ts)
    assert sol.success
    return sol.y.T


@pytest.mark.parametrize("tolerances,bound", [({}, 1e-4), (TIGHT, 1e-7)], ids=["default", "tight"])
@pytest.mark.parametrize("rpm", [8000.0, 12000.0])
def test_asc_transient_default_map(plant_fmu, default_map_path, rpm, tolerances, bound):
    """A trip from motoring into ASC on the saturated map: every 0.1 ms step's currents through the
    short circuit's ringing against an independent tight integration (at the default tolerances the
    plant's explicit steps carry the ringing, cvode_integrator.hpp; the same bound as freewheeling's)."""
    spline = MapSpline(default_map_path)
    w_m = rpm * math.pi / 30
    i0, h, n = (-150.0, 100.0), 1e-4, 200
    with Fmu(plant_fmu, w_m=w_m, i_d_start=i0[0], i_q_start=i0[1], **NO_FE, **tolerances) as f:
        got = run(f, 2, n, h)[:, :2]
    exact = current_trajectory(spline, 0.012, P * w_m, i0, h * np.arange(1, n + 1))
    assert exact[:, 0].min() > spline.i_d[0]  # on the map's grid (beyond it the plant continues the map its own way)
    peak = np.abs(exact).max()
    err = np.abs(got - exact).max() / peak
    print(f"ASC at {rpm:.0f} r/min, {tolerances or 'default tolerances'}: max current error {err:.1e} of the peak "
          f"{peak:.0f} A")
    assert peak > 400 and err < bound


# --- 3. freewheeling ------------------------------------------------------------------------------------

def onset_speed(psi_0, p=P, u_dc=U_DC):
    """The fundamental model's onset, |w_e| |psi_0| = 2 u_dc / pi, mechanical rad/s."""
    return 2 * u_dc / math.pi / (p * psi_0)


def test_freewheel_below_onset_blocks_once_and_creates_nothing(plant_fmu, linear_map):
    w_m = 0.8 * onset_speed(LIN["psi_m"])
    with Fmu(plant_fmu, flux_map=str(linear_map), R_s=R_LIN, w_m=w_m, i_d_start=-100.0, i_q_start=150.0,
             logging=True, **NO_FE, **TIGHT) as f:
        rows = run(f, 1, 200, 1e-4)
        first_zero = int(np.argmax(np.all(rows[:, :2] == 0.0, axis=1)))
        assert np.all(rows[first_zero:, :2] == 0.0), "the current came back"
        assert f.get("bridge_switchings") == 1
        assert np.allclose(rows[-1, 2:], [LIN["psi_m"], 0.0], rtol=0, atol=1e-15)
        print(f"below the onset: blocked after {first_zero + 1} steps of 0.1 ms, switchings "
              f"{f.get('bridge_switchings')}")
    # from zero current: nothing flows, nothing is created
    with Fmu(plant_fmu, flux_map=str(linear_map), R_s=R_LIN, w_m=w_m, **NO_FE, **TIGHT) as f:
        rows = run(f, 1, 100, 1e-4)
        assert np.all(rows[:, :2] == 0.0)
        assert f.get("E_elec") == 0.0 and f.get("E_cu") == 0.0 and f.get("bridge_switchings") == 0


def freewheel_steady_state(psi, R, om, k, guess):
    def residual(i):
        ps = psi(i)
        r = math.hypot(i[0], i[1])
        return [-k * i[0] / r - R * i[0] + om * ps[1], -k * i[1] / r - R * i[1] - om * ps[0]]

    ss = fsolve(residual, guess, xtol=1e-14)
    assert np.abs(residual(ss)).max() < 1e-8
    return ss


@pytest.mark.parametrize("ratio", [1.1, 1.6])
def test_freewheel_above_onset_linear(plant_fmu, linear_map, ratio):
    L_d, L_q, psi_m = LIN["L_d"], LIN["L_q"], LIN["psi_m"]
    w_m = ratio * onset_speed(psi_m)
    om = P * w_m
    ss = freewheel_steady_state(lambda i: np.array([L_d * i[0] + psi_m, L_q * i[1]]), R_LIN, om, K_BRIDGE,
                                [-psi_m / L_d * 0.5, -10.0])
    with Fmu(plant_fmu, flux_map=str(linear_map), R_s=R_LIN, w_m=w_m, **NO_FE, **TIGHT) as f:
        run(f, 1, 500, 1e-3)
        i = np.array(f.get("i_d", "i_q"))
        assert f.get("bridge_switchings") == 1  # conduction started once
        P_elec, T_e, i_dc, P_inv = f.get("P_elec", "T_e", "i_dc", "P_inv")
    err = np.abs(i - ss).max() / np.abs(ss).max()
    print(f"freewheeling at {ratio} x the onset: {i} A, fsolve {ss} A, error {err:.1e}; P_elec {P_elec:.0f} W, "
          f"T_e {T_e:.2f} N.m, i_dc {i_dc:.2f} A, P_inv {P_inv:.1f} W")
    assert err < 1e-6
    assert P_elec < 0 and i_dc < 0 and T_e * w_m < 0 and P_inv > 0
    assert P_elec == pytest.approx(-1.5 * K_BRIDGE * math.hypot(*i), rel=1e-12)


@pytest.mark.parametrize("ratio", [1.2, 1.8])
def test_freewheel_above_onset_default_map(plant_fmu, default_map_path, ratio):
    spline = MapSpline(default_map_path)
    psi_0 = float(spline.sd.ev(0.0, 0.0))
    w_m = ratio * onset_speed(psi_0)
    om = P * w_m
    ss = freewheel_steady_state(spline.psi, 0.012, om, K_BRIDGE, [-100.0, -20.0])
    with Fmu(plant_fmu, w_m=w_m, **NO_FE, **TIGHT) as f:
        run(f, 1, 500, 1e-3)
        i = np.array(f.get("i_d", "i_q"))
        assert f.get("bridge_switchings") == 1
    err = np.abs(i - ss).max() / np.abs(ss).max()
    print(f"default map freewheeling at {ratio} x the onset ({w_m * 30 / math.pi:.0f} r/min): {i} A, fsolve {ss} A, "
          f"error {err:.1e}")
    assert err < 1e-6


@pytest.mark.parametrize("tolerances,bound", [({}, 1e-4), (TIGHT, 1e-7)], ids=["default", "tight"])
@pytest.mark.parametrize("ratio", [1.3, 1.9])
def test_freewheel_conducting_trajectory_default_map(plant_fmu, default_map_path, ratio, tolerances, bound):
    """A trip from motoring above the onset, every 0.1 ms step's currents against an independent tight
    integration; at the default tolerances the steady conduction takes one explicit step per call (the
    linearised step with the bridge's voltage, freewheel_integrator.cpp), not CVODE's restarts."""
    spline = MapSpline(default_map_path)
    w_m = ratio * onset_speed(float(spline.sd.ev(0.0, 0.0)))
    i0, h, n = (-120.0, 150.0), 1e-4, 200
    with Fmu(plant_fmu, w_m=w_m, i_d_start=i0[0], i_q_start=i0[1], **NO_FE, **tolerances) as f:
        f.set(inverter_state=1)
        got, steps = [], []
        for _ in range(n):
            f.step(f.t, h)
            got.append(f.get("i_d", "i_q"))
            steps.append(f.get("cvode_steps"))
        assert f.get("bridge_switchings") == 0  # conducting throughout
    exact = current_trajectory(spline, 0.012, P * w_m, i0, h * np.arange(1, n + 1), k=K_BRIDGE)
    peak = np.abs(exact).max()
    err = np.abs(np.array(got) - exact).max() / peak
    print(f"{ratio} x the onset, {tolerances or 'default tolerances'}: max current error {err:.1e} of the peak "
          f"{peak:.0f} A; steps per call {np.mean(steps):.2f}, last 50 {np.mean(steps[-50:]):.2f}")
    assert err < bound
    if not tolerances:
        assert max(steps[-50:]) == 1


@pytest.mark.parametrize("h", [1e-3, 1e-4])
def test_freewheel_speed_sweeps_through_onset_without_chattering(plant_fmu, linear_map, h):
    """Speed falling from 1.3 to 0.7 of the onset and back in 600 steps: one block, one onset (with 0.1 ms
    steps a step ends a hair short of the zero, within its tolerance: the block is still counted)."""
    w_on = onset_speed(LIN["psi_m"])
    speeds = np.concatenate([np.linspace(1.3, 0.7, 300), np.linspace(0.7, 1.3, 300)]) * w_on
    with Fmu(plant_fmu, flux_map=str(linear_map), R_s=R_LIN, w_m=speeds[0], **NO_FE) as f:
        f.set(inverter_state=1)
        counts = []
        for w in speeds:
            f.set(w_m=w)
            f.step(f.t, h)
            counts.append((f.get("bridge_switchings"), f.get("cvode_steps")))
        c = np.array(counts)
    print(f"switchings {c[-1, 0]}, CVODE steps per 1 ms step: max {c[:, 1].max()}, mean {c[:, 1].mean():.1f}")
    assert c[-1, 0] == 3  # onset at the start (from zero current), block, onset
    assert c[:, 1].max() < 200  # no step-size collapse at i -> 0


def test_freewheel_trip_from_motoring_blocks(plant_fmu, default_map_path):
    """A trip from a motoring current at 0.9 of the onset: the current turns, falls to zero, blocks."""
    spline = MapSpline(default_map_path)
    w_m = 0.9 * onset_speed(float(spline.sd.ev(0.0, 0.0)))
    with Fmu(plant_fmu, w_m=w_m, i_d_start=-250.0, i_q_start=300.0, **TIGHT) as f:
        rows = run(f, 1, 100, 1e-4)
        assert f.get("bridge_switchings") == 1
        assert np.all(rows[-1, :2] == 0.0)


# --- 4. energy over a trip in each state ---------------------------------------------------------------

def magnetic_energy(spline_psi_to_i, psi_a, psi_b, n=400):
    """1.5 int i . dpsi along the straight path from psi_a to psi_b (Gauss-Legendre)."""
    x, wts = np.polynomial.legendre.leggauss(n)
    d = np.asarray(psi_b) - np.asarray(psi_a)
    total = 0.0
    for s, wt in zip(0.5 * (x + 1), 0.5 * wts):
        total += wt * np.dot(spline_psi_to_i(np.asarray(psi_a) + s * d), d)
    return 1.5 * total


@pytest.mark.parametrize("state,ratio", [(2, 1.5), (1, 1.5), (1, 0.9)])
def test_energy_balance_over_a_trip(plant_fmu, linear_map, state, ratio):
    L_d, L_q, psi_m = LIN["L_d"], LIN["L_q"], LIN["psi_m"]
    w_m = ratio * onset_speed(psi_m)
    with Fmu(plant_fmu, flux_map=str(linear_map), R_s=R_LIN, w_m=w_m, i_d_start=-200.0, i_q_start=250.0,
             **TIGHT) as f:
        psi_a = f.get("psi_d", "psi_q")
        run(f, state, 300, 1e-4)
        psi_b = f.get("psi_d", "psi_q")
        E = dict(zip(("E_elec", "E_cu", "E_mech", "E_fe", "E_inv"), f.get("E_elec", "E_cu", "E_mech", "E_fe", "E_inv")))
    dW = magnetic_energy(lambda psi: np.array([(psi[0] - psi_m) / L_d, psi[1] / L_q]), psi_a, psi_b)
    residual = E["E_elec"] - (E["E_cu"] + E["E_mech"] + E["E_fe"] + dW)
    print(f"state {state} at {ratio} x onset: {E}, dW {dW:.6g} J, residual {residual:.3e} J "
          f"({residual / abs(E['E_mech']):.1e} of the shaft energy)")
    assert E["E_mech"] < 0  # energy taken from the shaft
    assert abs(residual) < 1e-6 * abs(E["E_mech"])


# --- 5. the FMU interface ---------------------------------------------------------------------------------

def test_inverter_state_out_of_range_refused(fmu_instances):
    inst = fmu_instances("IpmsmPlant", logging_on=True)
    inst.init(w_m=800.0)
    for bad in (-1, 3, 1 << 30):
        raw.refused(inst, inst.set_status, "inverter_state", bad, match="inverter_state")
    assert inst.step(1e-4) == raw.OK
    assert inst.set_status("inverter_state", 2) == raw.OK
    assert inst.step(1e-4) == raw.OK
    i_d, i_q = inst.get("i_d", "i_q")
    assert math.isfinite(i_d) and math.isfinite(i_q)


def test_fmu_state_carries_the_bridge(fmu_instances, default_map_path):
    """A state saved while blocked, restored after a conducting stretch: the same steps again."""
    inst = fmu_instances("IpmsmPlant", logging_on=True)
    psi_0 = float(MapSpline(default_map_path).sd.ev(0.0, 0.0))
    inst.init(w_m=0.9 * onset_speed(psi_0), i_d_start=-50.0, i_q_start=80.0)
    inst.set(inverter_state=1)
    for _ in range(50):
        assert inst.step(1e-4) == raw.OK
    saved, t_saved = inst.serialize(inst.get_state()), inst.t
    names = ("i_d", "i_q", "psi_d", "psi_q", "E_elec", "bridge_switchings", "P_inv")

    def trace():
        out = []
        for w in (0.9, 1.3, 1.3, 0.9, 0.9):
            inst.set(w_m=w * onset_speed(psi_0))
            for _ in range(10):
                assert inst.step(1e-4) == raw.OK, inst.log.text()
                out.append(inst.get(*names))
        return out

    assert inst.replays(saved, t_saved, trace)


@pytest.mark.skipif(not (BASELINE / "IpmsmPlant.fmu").exists(), reason="no baseline FMU")
def test_switching_bit_for_bit_as_the_baseline(plant_fmu, default_map_path):
    """inverter_state = 0: every output the FMU had before the faults has the same bits."""
    def trace(path, **extra):
        with Fmu(path, w_m=600.0, i_d_start=-80.0, i_q_start=120.0, **extra) as f:
            names = [v for v, var in f.vars.items() if var.causality == "output" and var.type == "Real"]
            rows = []
            t = 0.0
            for k in range(300):
                f.set(u_d=-60.0 + 0.1 * k, u_q=150.0 - 0.05 * k, w_m=600.0 + k)
                f.step(t, 1e-4)
                t += 1e-4
                rows.append(f.get(*names))
            return names, np.array(rows)

    names_base, base = trace(BASELINE / "IpmsmPlant.fmu")
    names_now, now = trace(plant_fmu, inverter_state=0)
    cols = [names_now.index(n) for n in names_base]
    assert base.tobytes() == now[:, cols].tobytes()
