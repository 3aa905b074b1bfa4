"""The machine's thermal network (fmu_src/thermal/, stepped by build/bin/thermal_trace) against
an independent implementation of the same published network in numpy/scipy: the steady state
from the conductance matrix, the step response from the generalised eigen-decomposition and from
scipy's expm, a run with time-varying losses against solve_ivp, and the heat balance.

The reference network below is written from the source (Wallscheid's low-order LPTN as
implemented in github.com/wkirgsn/thermal-nn aux/lptn_model.py and github.com/wkirgsn/diss-wk
src/mawkutils/topology.py, docs/thermal.md), not from the C++."""
from __future__ import annotations

import subprocess
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.linalg import eigh, expm

from scenarios.core import paths

TRACE = paths.BUILD_DIR / "bin" / "thermal_trace"
RPM = 2.0 * np.pi / 60.0  # rad/s per r/min
ZERO_C = 273.15
YOKE, TOOTH, WINDING, MAGNET = range(4)


@dataclass(frozen=True)
class Network:
    """Wallscheid's LPTN (values: the source's coefficient names in the comments)."""
    C_stator_yoke: float = 6.5093e3   # caps1
    C_stator_tooth: float = 0.437127e3  # caps2
    C_winding: float = 3.5105e3       # caps3
    C_magnet: float = 1.0666e4        # caps0
    R_yoke_winding: float = 0.0375    # const_Rs_sy_sw
    R_yoke_tooth: float = 0.0707      # const_Rs_sy_st
    R_tooth_winding: float = 0.0899   # const_Rs_sw_st
    R_coolant_yoke: float = 18e-3     # lin_Rs_bias
    k_coolant_yoke: float = -54e-4    # lin_Rs_slope

    def args(self) -> list[str]:
        base = Network()
        return [f"{k}={v!r}" for k, v in self.__dict__.items() if v != getattr(base, k)]

    def C(self) -> np.ndarray:
        return np.array([self.C_stator_yoke, self.C_stator_tooth, self.C_winding, self.C_magnet])

    def matrices(self, w_m: float, T_c: float) -> tuple[np.ndarray, np.ndarray]:
        """K (W/K, 4x4) and G_b (W/K, 4x2: coolant, ambient) with C dT/dt = P + G_b T_b - K T."""
        n = min(abs(w_m) / (6000.0 * RPM), 1.0)
        c = min(max((T_c - ZERO_C) / 100.0, 0.0), 1.0)
        r_exp = lambda a, b, s: a * np.exp(-n / b) + s  # noqa: E731
        R = {(YOKE, WINDING): self.R_yoke_winding, (YOKE, TOOTH): self.R_yoke_tooth,
             (TOOTH, WINDING): self.R_tooth_winding,
             (TOOTH, MAGNET): r_exp(1.7275, 0.1573, 0.3039), (WINDING, MAGNET): r_exp(0.8486, 0.1428, 0.2319)}
        K = np.zeros((4, 4))
        for (i, j), r in R.items():
            K[i, j] = K[j, i] = -1.0 / r
        Gb = np.zeros((4, 2))
        Gb[YOKE, 0] = 1.0 / (self.R_coolant_yoke * (1.0 + self.k_coolant_yoke * (100.0 * c - 20.0)))
        Gb[MAGNET, 0] = 1.0 / (0.3528 - 0.2484 * n + 0.0276 * c + 0.3331 * n * c)
        Gb[MAGNET, 1] = 1.0 / r_exp(0.6349, 0.1184, 0.1205)
        K[np.diag_indices(4)] = -K.sum(axis=1) + Gb.sum(axis=1)
        return K, Gb

    @staticmethod
    def losses(P_cu: float, P_fe: float, w_m: float, I_rms: float) -> np.ndarray:
        n = min(abs(w_m) / (6000.0 * RPM), 1.0)
        i = min(abs(I_rms) / 256.0, 1.0)
        k1 = min(max(0.5441 + 78e-4 * n + 0.0352 * i - 0.7438 * n * i, 0.0), 1.0)
        return np.array([0.8655 * k1 * P_fe, (1 - 0.8655) * k1 * P_fe, P_cu, (1 - k1) * P_fe])


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
