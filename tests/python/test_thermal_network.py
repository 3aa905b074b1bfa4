"""The machine's thermal network (fmu_src/thermal/, stepped by build/bin/thermal_trace) against
an independent implementation of the same published network in numpy/scipy: the steady state
from the conductance matrix, the step response from the generalised eigen-decomposition and from
scipy's expm, a run with time-varying losses against solve_ivp, and the heat balance.

The reference network (thermal_reference.py) is written from the source, not from the C++."""
from __future__ import annotations

import subprocess

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.linalg import eigh, expm
from thermal_reference import RPM, WINDING, Network

from scenarios.core import paths

TRACE = paths.BUILD_DIR / "bin" / "thermal_trace"

# A second network the defaults were not designed for: a light, poorly coupled tooth (stiff).
STIFF = Network(C_stator_tooth=20.0, R_yoke_tooth=0.5, R_tooth_winding=0.01, C_winding=800.0)
NETWORKS = [pytest.param(Network(), id="wallscheid"), pytest.param(STIFF, id="stiff")]


def run_trace(net: Network, theta0: float, rows) -> np.ndarray:
    """rows: (h, E_cu, E_fe, w_m, I_rms, T_coolant, T_ambient) per step -> (steps, 8) array."""
    if not TRACE.exists():
        pytest.fail(f"{TRACE} is missing: build first (cmake --build build --target thermal_trace)")
    text = "".join(",".join(repr(float(x)) for x in r) + "\n" for r in rows)
    out = subprocess.run([str(TRACE), repr(theta0), *net.args()], input=text, capture_output=True, text=True,
                         check=True).stdout
    return np.loadtxt(out.splitlines(), delimiter=",", ndmin=2)


@pytest.mark.parametrize("net", NETWORKS)
@pytest.mark.parametrize("rpm", [0.0, 2500.0, 9000.0])
def test_steady_state_is_the_conductance_matrix_solution(net, rpm):
    w, I, Tc, Ta = rpm * RPM, 180.0, 338.15, 303.15
    P_cu, P_fe = 1500.0, 700.0
    K, Gb = net.matrices(w, Tc)
    expected = np.linalg.solve(K, net.losses(P_cu, P_fe, w, I) + Gb @ [Tc, Ta])
    h = 1e6  # s: hundreds of the slowest time constants
    got = run_trace(net, 293.15, [(h, P_cu * h, P_fe * h, w, I, Tc, Ta)])[-1, :4]
    assert np.max(np.abs(got - expected)) < 1e-6, got - expected


@pytest.mark.parametrize("net", NETWORKS)
def test_step_response_is_the_eigen_decomposition_solution(net):
    w, I, Tc, Ta = 4000.0 * RPM, 220.0, 323.15, 298.15
    P_cu, P_fe = 2500.0, 1200.0
    K, Gb = net.matrices(w, Tc)
    C = net.C()
    q = net.losses(P_cu, P_fe, w, I) + Gb @ [Tc, Ta]
    theta_ss = np.linalg.solve(K, q)
    lam, Phi = eigh(K, np.diag(C))  # K Phi = C Phi diag(lam), Phi^T C Phi = I
    theta0 = np.full(4, 283.15)
    hs = [0.5, 3.0, 40.0, 200.0, 1000.0]
    rows = [(h, P_cu * h, P_fe * h, w, I, Tc, Ta) for h in hs]
    got = run_trace(net, 283.15, rows)[:, :4]
    t = np.cumsum(hs)
    for k, tk in enumerate(t):
        by_eig = theta_ss + Phi @ (np.exp(-lam * tk) * (Phi.T @ (C * (theta0 - theta_ss))))
        by_expm = theta_ss + expm(-tk * (K / C[:, None])) @ (theta0 - theta_ss)
        assert np.max(np.abs(got[k] - by_eig)) < 1e-6, (tk, got[k] - by_eig)
        assert np.max(np.abs(by_expm - by_eig)) < 1e-6


def _drive_profile(t: float) -> tuple[float, float, float]:
    """A repeated acceleration-like load: speed (rad/s), RMS current (A), coolant (K) at time t (s)."""
    phase = (t % 120.0) / 120.0
    w = 8000.0 * RPM * np.sin(np.pi * phase) ** 2
    I = 60.0 + 240.0 * np.exp(-((phase - 0.25) / 0.08) ** 2) + 40.0 * np.sin(2 * np.pi * t / 37.0) ** 2
    Tc = 318.15 + 15.0 * (1.0 - np.exp(-t / 600.0))
    return w, I, Tc


def _losses_at(t: float) -> tuple[float, float]:
    w, I, _ = _drive_profile(t)
    return 3.0 * 0.014 * I**2, 1.1 * abs(w) + 2.5e-4 * w**2  # W: copper, iron (a plausible shape)


# (network, communication step, run length): the step well below the fastest time constant
# (Wallscheid's network: 15 s; the stiff one: 0.19 s), where holding a step's mean loss is accurate.
@pytest.mark.parametrize("net, h, t_end", [pytest.param(Network(), 1.0, 1800.0, id="wallscheid"),
                                           pytest.param(STIFF, 0.05, 300.0, id="stiff")])
def test_time_varying_losses_against_solve_ivp(net, h, t_end):
    """Losses varying within each step (the C++ gets their exact integrals), speed and coolant held
    per step as an FMU holds its inputs: temperatures within 0.01 K of a tight solve_ivp, the heat
    balance within 1e-6 of the throughput, the heat into the coolant within 1e-6 of it too."""
    Ta = 303.15
    edges = np.arange(0.0, t_end + h / 2, h)
    C = net.C()
    rows = []
    for a, b in zip(edges[:-1], edges[1:]):
        w, I, Tc = _drive_profile(a)
        E_cu = quad(lambda s: _losses_at(s)[0], a, b, epsabs=1e-12, epsrel=1e-13)[0]
        E_fe = quad(lambda s: _losses_at(s)[1], a, b, epsabs=1e-12, epsrel=1e-13)[0]
        rows.append((b - a, E_cu, E_fe, w, I, Tc, Ta))
    got = run_trace(net, 298.15, rows)

    def rhs(t, y, w, I, Tc, K, Gb):
        P_cu, P_fe = _losses_at(t)
        theta = y[:4]
        dtheta = (net.losses(P_cu, P_fe, w, I) + Gb @ [Tc, Ta] - K @ theta) / C
        return np.concatenate([dtheta, [Gb[:, 0] @ (theta - Tc)]])

    y = np.concatenate([np.full(4, 298.15), [0.0]])
    worst = 0.0
    for k, (_, _, _, w, I, Tc, _) in enumerate(rows):  # one solve per held interval: the inputs jump
        K, Gb = net.matrices(w, Tc)
        sol = solve_ivp(rhs, (edges[k], edges[k + 1]), y, method="DOP853", rtol=1e-11, atol=1e-9,
                        args=(w, I, Tc, K, Gb))
        y = sol.y[:, -1]
        worst = max(worst, np.max(np.abs(got[k, :4] - y[:4])))
    print(f"\nworst temperature difference {worst:.3g} K over {len(rows)} steps of {h} s")
    assert worst < 0.01, worst
    E_loss, E_stored, E_coolant, E_ambient = got[-1, 4:]
    assert got[-1, WINDING] > 298.15 + 20.0  # the run heats the winding: a real test
    assert abs(E_loss - E_stored - E_coolant - E_ambient) < 1e-6 * E_loss
    print(f"balance residual {(E_loss - E_stored - E_coolant - E_ambient) / E_loss:.3g}, coolant heat vs "
          f"solve_ivp {(E_coolant - y[4]) / E_loss:.3g} of the throughput {E_loss:.4g} J")
    assert abs(E_coolant - y[4]) < 1e-6 * E_loss, (E_coolant, y[4])


def test_bad_parameters_exit_2_naming_them():
    r = subprocess.run([str(TRACE), "293.15", "C_winding=-5"], input="", capture_output=True, text=True)
    assert r.returncode == 2 and "C_winding" in r.stderr
    r = subprocess.run([str(TRACE), "293.15"], input="0.1,nan,0,0,0,300,300\n", capture_output=True, text=True)
    assert r.returncode == 2 and "losses" in r.stderr


def test_the_cpp_tests_are_built():
    """The GoogleTest cases of tests/cpp/test_thermal_network.cpp are in build/bin/unit_tests (a
    test list that left the file out would drop them silently)."""
    unit_tests = paths.BUILD_DIR / "bin" / "unit_tests"
    listed = subprocess.run([str(unit_tests), "--gtest_list_tests"], capture_output=True, text=True, check=True).stdout
    assert "ThermalNetwork." in listed
