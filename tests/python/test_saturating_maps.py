"""The controller FMU on strongly saturating maps (tools/saturating_map.py, issue 12): T_max and
the current commands against the brute-force global optimum (brute_force.py: dense sampling,
then SLSQP, on scipy's own spline of the map), in all regions and four quadrants, for recursion
2 and the 2-D tables (methods 2, 3), on fresh instances and on warm ones stepped through random
histories (the answer must depend on the inputs only).

Acceptance (issue 12): <= 0.1 % excess current over the least-current point for the commanded
torque, and torque (T_max, the torque the commands make) within 0.1 % of T_max.
On these maps the torque along the current circle has two local maxima (q-axis saturation
makes the machine reverse-salient at high i_q); a solver that polishes from one start finds
either. Cases the code of ed0f875 gets wrong are marked xfail(strict): the fix flips them.
"""
from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from scenarios.cosim.fmu import set_values
from scenarios.maps.flux_map import read_flux_map
from tools.saturating_map import K_U, U_DC, W_M_MAX, SaturatingMachine, write_map

from brute_force import Drive, max_torque, min_current

H = 1e-4                 # s, communication step
EXCESS_CURRENT = 1e-3    # relative to the optimum's current (issue 12)
TORQUE_TOL = 1e-3        # relative to T_max (issue 12)
T_MAGNET_REF = 293.15    # K
K_PSI_T = -0.0012        # 1/K
# Fresh and warm instances: the same problem, so the same answer. A different local optimum is
# tens of percent away; a warm-started polish that stops at its convergence test differs by
# about 1e-8 (measured on ed0f875 where it finds the global optimum).
SAME_ANSWER = 1e-6

LOCAL_OPTIMUM = "issue 12: local optimum (two torque maxima along the current circle)"


def _xfail(reason=LOCAL_OPTIMUM):
    return pytest.mark.xfail(strict=True, reason=reason)


def machine_id(m: SaturatingMachine) -> str:
    d = "none" if m.I_ds_ratio is None else f"{m.I_ds_ratio:g}"
    return f"Is{m.I_s_ratio:g}-Ids{d}-x{m.cross:g}" + ("" if m.L_d == SaturatingMachine.L_d else f"-Ld{m.L_d:g}")


# The default run: q-axis saturation from hard (0.2) to mild (1.0) I_max, with and without
# d-axis saturation and 15 % cross-saturation (the family's corners that are monotone).
FAST = [
    SaturatingMachine(0.3, None, 0.0),
    SaturatingMachine(0.3, 0.5, 0.15),
    SaturatingMachine(0.2, None, 0.15),
    SaturatingMachine(1.0, 0.5, 0.15),
]
SLOW = [
    SaturatingMachine(0.2, None, 0.0),
    SaturatingMachine(0.2, 0.5, 0.0),
    SaturatingMachine(0.3, 1.0, 0.15),
    SaturatingMachine(0.5, None, 0.15),
    SaturatingMachine(0.5, 0.5, 0.0),
    SaturatingMachine(0.5, None, 0.15, L_d=3e-4),  # two maxima of nearly equal torque
    SaturatingMachine(0.7, 0.5, 0.15),
    SaturatingMachine(1.0, None, 0.0),
]


class FreshController:
    """Controller FMU instances, each new (instantiated, initialised) for one step: no history.
    The FMU is extracted once."""

    def __init__(self, path, **parameters):
        self.md = read_model_description(str(path))
        self.dir = extract(str(path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.parameters = parameters

    def _set(self, **values):
        set_values(self.slave, self.vars, **values)

    def answer(self, op: dict) -> tuple:
        # freeInstance unloads the library (fmpy): a new slave each time.
        s = self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                                   modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="fresh")
        s.instantiate()
        try:
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
            self._set(**self.parameters, **op)
            s.exitInitializationMode()
            s.doStep(currentCommunicationPoint=0.0, communicationStepSize=H)
            return read_answer(lambda *n: [self._get(x) for x in n])
        finally:
            s.terminate()
            s.freeInstance()

    def _get(self, name):
        v = self.vars[name]
        return getattr(self.slave, "get" + v.type)([v.valueReference])[0]


def read_answer(get) -> tuple:
    i_d, i_q, T_cmd, T_max, region = get("i_d_ref", "i_q_ref", "T_cmd", "T_max", "region")
    return float(i_d), float(i_q), float(T_cmd), float(T_max), int(region)


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    """machine id -> (path, FluxMap), generated on first use."""
    out, cache = tmp_path_factory.mktemp("saturating_maps"), {}

    def get(m: SaturatingMachine):
        key = machine_id(m)
        if key not in cache:
            path = out / f"{key}.csv"
            write_map(path, m)
            cache[key] = (path, read_flux_map(path))
        return cache[key]
    return get


def parameters(m: SaturatingMachine, path) -> dict:
    return dict(flux_map=str(path), pole_pairs=m.pole_pairs, R_s=m.R_s, I_max=m.I_max, k_u=K_U,
                k_psi_T=K_PSI_T, T_magnet_ref=T_MAGNET_REF)


def drive_at(m: SaturatingMachine, fmap, op: dict) -> Drive:
    shift = fmap.psi_m * K_PSI_T * (op["T_magnet"] - T_MAGNET_REF)
    return Drive(fmap, m.pole_pairs, m.R_s, m.I_max, K_U * op["u_dc"] / math.sqrt(3), m.pole_pairs * op["w_m"], shift)


def peak_torque(m: SaturatingMachine, fmap) -> float:
    return max_torque(drive_at(m, fmap, dict(w_m=0.0, u_dc=U_DC, T_magnet=T_MAGNET_REF)), 1.0)[0]


def operating_points(rng, T_peak: float, n_per_cell: int = 1):
    """Stratified: four quadrants x three speed bands (MTPA; field weakening; deep field
    weakening and MTPV) x a torque within reach or beyond it; conditions random."""
    for T_sign in (1, -1):
        for w_sign in (1, -1):
            for lo, hi in ((0.0, 0.3), (0.35, 0.65), (0.7, 1.0)):
                for t_lo, t_hi in ((0.1, 0.9), (1.05, 1.4)):
                    for _ in range(n_per_cell):
                        yield dict(T_ref=float(T_sign * rng.uniform(t_lo, t_hi) * T_peak),
                                   w_m=float(w_sign * rng.uniform(lo, hi) * W_M_MAX),
                                   u_dc=float(rng.uniform(0.75, 1.1) * U_DC),
                                   T_magnet=float(rng.uniform(253.15, 393.15)))


def reference(m, fmap, op) -> dict:
    """The brute-force optimum at op: T_max, the commanded torque, the least current for it."""
    d = drive_at(m, fmap, op)
    sign = -1.0 if op["T_ref"] < 0 else 1.0
    T_max, _ = max_torque(d, sign)
    T_cmd = sign * min(abs(op["T_ref"]), T_max)
    I_min, _ = min_current(d, T_cmd, max(T_max, 1e-9))
    return dict(d=d, T_max=T_max, T_cmd=T_cmd, I_min=I_min)


def deviations(m, answer, ref) -> dict:
    """What the acceptance criteria measure, for one answer against its reference."""
    i_d, i_q, T_cmd, T_max, _ = answer
    d, scale = ref["d"], max(ref["T_max"], 1.0)
    I = math.hypot(i_d, i_q)
    if ref.get("T_max_only"):
        return dict(T_max=(abs(T_max) - ref["T_max"]) / scale, torque=0.0, excess=0.0, I=I / m.I_max,
                    V=float(d.voltage(i_d, i_q)) / d.V_max)
    return dict(
        T_max=(abs(T_max) - ref["T_max"]) / scale,
        torque=(float(d.torque(i_d, i_q)) - ref["T_cmd"]) / scale,
        excess=((I - ref["I_min"]) / ref["I_min"]
                if np.isfinite(ref["I_min"]) and ref["I_min"] > 0.02 * m.I_max else 0.0),
        I=I / m.I_max, V=float(d.voltage(i_d, i_q)) / d.V_max)


def assert_optimal(m, label, ops, answers, refs):
    devs = [deviations(m, a, r) for a, r in zip(answers, refs)]
    regions = Counter(a[4] for a in answers)
    worst = {k: max((dv[k] for dv in devs), key=abs) for k in ("T_max", "torque", "excess")}
    print(f"\n[{label}] {len(ops)} points, regions {dict(sorted(regions.items()))}: T_max {worst['T_max']:+.3%}, "
          f"torque {worst['torque']:+.3%} of T_max, excess current {worst['excess']:+.3%}; "
          f"I/I_max <= {max(dv['I'] for dv in devs):.5f}, V/V_max <= {max(dv['V'] for dv in devs):.5f}")
    bad = [(op, a, r["T_max"], r["I_min"], dv) for op, a, r, dv in zip(ops, answers, refs, devs)
           if not (abs(dv["T_max"]) <= TORQUE_TOL and abs(dv["torque"]) <= TORQUE_TOL and dv["excess"] <= EXCESS_CURRENT
                   and dv["I"] <= 1 + 1e-3 and dv["V"] <= 1 + 1e-3)]
    assert not bad, f"{label}: {len(bad)} of {len(ops)} points off the optimum, e.g. {bad[:3]}"


def run_fresh(controller_fmu, m, path, ops, **extra):
    fresh = FreshController(controller_fmu, **parameters(m, path), **extra)
    return [fresh.answer(op) for op in ops]


def run_warm(controller_fmu, m, path, ops, rng, T_peak, **extra):
    """One instance through a random history before each point (new problems, held inputs
    that hit the command cache, and steps with the same T_ref at another speed), then the point
    held for two steps: both answers are returned."""
    from scenarios.cosim.fmu import Fmu
    answers = []
    k = 0
    with Fmu(controller_fmu, **parameters(m, path), **extra) as c:
        for op in ops:
            for _ in range(int(rng.integers(2, 7))):
                h = dict(T_ref=float(rng.uniform(-1.4, 1.4) * T_peak), w_m=float(rng.uniform(-1, 1) * W_M_MAX),
                         u_dc=float(rng.uniform(0.75, 1.1) * U_DC), T_magnet=float(rng.uniform(253.15, 393.15)))
                if rng.uniform() < 0.3:
                    h["T_ref"] = op["T_ref"]
                for _ in range(int(rng.integers(1, 3))):
                    c.set(**h)
                    c.step(k * H, H)
                    k += 1
            c.set(**op)
            pair = []
            for _ in range(2):
                c.step(k * H, H)
                k += 1
                pair.append(read_answer(c.get))
            answers.append(pair)
    return answers


def assert_same(label, fresh, warm, m, T_peak):
    worst = 0.0
    for f, pair in zip(fresh, warm):
        for w in pair:
            diff = max(abs(f[0] - w[0]) / m.I_max, abs(f[1] - w[1]) / m.I_max,
                       abs(f[2] - w[2]) / T_peak, abs(f[3] - w[3]) / T_peak, float(f[4] != w[4]))
            worst = max(worst, diff)
    print(f"\n[{label}] warm vs fresh: largest difference {worst:.3e} (of I_max, T_peak)")
    assert worst <= SAME_ANSWER, f"{label}: the answer depends on the instance's history ({worst:.3e})"


# --- the generator ------------------------------------------------------------------------------

@pytest.mark.parametrize("m", [pytest.param(m, id=machine_id(m)) for m in FAST + SLOW])
def test_generated_map_is_legal_monotone_and_reciprocal(maps, m):
    """As written to CSV and read back: a grid covering I_max, the issue's q-axis shape at
    i_d = 0, PM flux on +d, a positive-definite incremental inductance (finite differences of
    the closed form, independent of its analytic Hessian) and reciprocity."""
    path, fmap = maps(m)
    assert fmap.i_d[0] <= -m.I_max and fmap.i_d[-1] >= m.I_max and fmap.i_q[0] <= -m.I_max and fmap.i_q[-1] >= m.I_max
    j0 = int(np.argmin(np.abs(fmap.i_d)))
    assert fmap.i_d[j0] == 0.0
    np.testing.assert_allclose(fmap.psi_q[j0], m.L_q * fmap.i_q / np.sqrt(1 + (fmap.i_q / m.I_s) ** 2), rtol=1e-12)
    assert fmap.psi_m == pytest.approx(m.psi_m, rel=1e-12)
    ax = np.linspace(-m.grid_span_ratio * m.I_max, m.grid_span_ratio * m.I_max, 301)
    I_d, I_q = np.meshgrid(ax, ax, indexing="ij")
    e = 1e-3  # A
    dd = [(a - b) / (2 * e) for a, b in zip(m.flux(I_d + e, I_q), m.flux(I_d - e, I_q))]  # d/di_d of (psi_d, psi_q)
    dq = [(a - b) / (2 * e) for a, b in zip(m.flux(I_d, I_q + e), m.flux(I_d, I_q - e))]
    np.testing.assert_allclose(dq[0], dd[1], atol=1e-9 * m.L_q)  # dpsi_d/di_q = dpsi_q/di_d
    lam_min = 0.5 * (dd[0] + dq[1]) - np.sqrt(0.25 * (dd[0] - dq[1]) ** 2 + dd[1] ** 2)
    assert lam_min.min() > 0
    assert np.all(np.diff(fmap.psi_d, axis=0) > 0) and np.all(np.diff(fmap.psi_q, axis=1) > 0)
    # Strongly saturating: at I_max the q-axis incremental inductance is a fraction of L_q.
    assert dq[1][150, -1] < 0.7 * m.L_q


def test_generator_refuses_a_non_monotone_machine(tmp_path):
    with pytest.raises(ValueError, match="not positive definite"):
        write_map(tmp_path / "bad.csv", SaturatingMachine(0.2, 0.3, 0.15))
    assert not (tmp_path / "bad.csv").exists()


# --- recursion 2 (Ferrari, optimal on the map) -------------------------------------------------

def _cases(family, xfails):
    return [pytest.param(m, id=machine_id(m), marks=[_xfail()] if machine_id(m) in xfails else [])
            for m in family]


# Failing on ed0f875 (measured, see the report of the branch h/satmaps).
# All fixed by h/controller (recursion 2 bracketed on the map's current circles): none left.
FAST_FAILING: set[str] = set()
FAIL_FRESH_R2 = FAST_FAILING
FAIL_WARM_R2 = FAST_FAILING


def _recursion2_optimal(controller_fmu, maps, m, n_per_cell, seed):
    path, fmap = maps(m)
    T_peak = peak_torque(m, fmap)
    ops = list(operating_points(np.random.default_rng(seed), T_peak, n_per_cell))
    refs = [reference(m, fmap, op) for op in ops]
    answers = run_fresh(controller_fmu, m, path, ops, method=1, recursion=2)
    assert_optimal(m, f"{machine_id(m)}, recursion 2, fresh", ops, answers, refs)


def _recursion2_history(controller_fmu, maps, m, n_per_cell, seed):
    path, fmap = maps(m)
    T_peak = peak_torque(m, fmap)
    rng = np.random.default_rng(seed)
    ops = list(operating_points(rng, T_peak, n_per_cell))
    fresh = run_fresh(controller_fmu, m, path, ops, method=1, recursion=2)
    warm = run_warm(controller_fmu, m, path, ops, rng, T_peak, method=1, recursion=2)
    assert_same(f"{machine_id(m)}, recursion 2", fresh, warm, m, T_peak)


@pytest.mark.parametrize("m", _cases(FAST, FAIL_FRESH_R2))
def test_recursion2_fresh_is_the_global_optimum(controller_fmu, maps, m):
    _recursion2_optimal(controller_fmu, maps, m, 1, 12)


@pytest.mark.parametrize("m", _cases(FAST, FAIL_WARM_R2))
def test_recursion2_warm_equals_fresh(controller_fmu, maps, m):
    _recursion2_history(controller_fmu, maps, m, 1, 13)


SLOW_FAILING: set[str] = set()
FAIL_FRESH_R2_SLOW = SLOW_FAILING
FAIL_WARM_R2_SLOW = SLOW_FAILING


@pytest.mark.slow
@pytest.mark.parametrize("m", _cases(SLOW + FAST, FAIL_FRESH_R2 | FAIL_FRESH_R2_SLOW))
def test_recursion2_fresh_is_the_global_optimum_more(controller_fmu, maps, m):
    _recursion2_optimal(controller_fmu, maps, m, 4, 22)


@pytest.mark.slow
@pytest.mark.parametrize("m", _cases(SLOW + FAST, FAIL_WARM_R2 | FAIL_WARM_R2_SLOW))
def test_recursion2_warm_equals_fresh_more(controller_fmu, maps, m):
    _recursion2_history(controller_fmu, maps, m, 4, 23)


# --- the 2-D tables (methods 2, 3): exact at their nodes ---------------------------------------

LUT_N = 41  # the FMU's default table size (lut_n_torque = lut_n_speed)
V_MAX_LUT = K_U * U_DC / math.sqrt(3)  # the tables are built at u_dc = lut_u_dc = U_DC


def table_speeds(m, fmap, method, fresh) -> list[float]:
    """The speeds of the table's second-axis nodes (method 2: speed; method 3: psi_s = V_max /
    omega, whose top is 1.1 times the stator flux at the zero-speed peak, computed as the table
    does from the peak's currents, read from the table's own top node)."""
    if method == 2:
        return [W_M_MAX * j / (LUT_N - 1) for j in range(LUT_N)]
    i_d, i_q, *_ = fresh.answer(dict(T_ref=1e9, w_m=0.0, u_dc=U_DC, T_magnet=T_MAGNET_REF))
    psi_d, psi_q = fmap.flux(i_d, i_q)
    psi_lo = V_MAX_LUT / (m.pole_pairs * W_M_MAX)
    psi_hi = 1.10 * math.hypot(float(psi_d), float(psi_q))  # kFluxAxisHeadroom in torque_table.cpp
    return [V_MAX_LUT / (psi_lo + (psi_hi - psi_lo) * j / (LUT_N - 1)) / m.pole_pairs for j in range(LUT_N)]


def table_nodes(m, fmap, method, fresh, rng, n_speeds=3):
    """Operating points on the table's nodes, at the conditions it was built for: there its
    bilinear interpolation returns a node's entry, the exact solver's answer. Torques: a node
    below the reference T_max (a command above it is clamped, between nodes)."""
    T_peak = abs(fresh.answer(dict(T_ref=1e9, w_m=0.0, u_dc=U_DC, T_magnet=T_MAGNET_REF))[3])
    speeds = table_speeds(m, fmap, method, fresh)
    for j in sorted(rng.choice(len(speeds), n_speeds, replace=False)):
        for T_sign in (1, -1):
            for w_sign in (1, -1):
                op = dict(T_ref=T_sign * T_peak, w_m=w_sign * speeds[j], u_dc=U_DC, T_magnet=T_MAGNET_REF)
                T_max = max_torque(drive_at(m, fmap, op), T_sign)[0]
                below = [k for k in range(LUT_N // 2 + 1, LUT_N)
                         if T_peak * (2.0 * k / (LUT_N - 1) - 1.0) < 0.999 * T_max]
                if below:
                    k = int(rng.choice(below))
                    op["T_ref"] = T_sign * T_peak * (2.0 * k / (LUT_N - 1) - 1.0)
                yield op  # else T_ref = T_peak: T_max is checked, the command is clamped


def _tables_optimal(controller_fmu, maps, m, method, seed):
    path, fmap = maps(m)
    fresh = FreshController(controller_fmu, **parameters(m, path), method=method, lut_u_dc=U_DC,
                            lut_T_magnet=T_MAGNET_REF, lut_n_torque=LUT_N, lut_n_speed=LUT_N)
    ops = list(table_nodes(m, fmap, method, fresh, np.random.default_rng(seed)))
    answers = [fresh.answer(op) for op in ops]
    refs = [reference(m, fmap, op) for op in ops]
    # Clamped commands (T_ref above T_max) lie between torque nodes: T_max only.
    for op, r in zip(ops, refs):
        r["T_max_only"] = abs(op["T_ref"]) >= r["T_max"]
    assert_optimal(m, f"{machine_id(m)}, method {method} at its nodes", ops, answers, refs)


def _tables_history(controller_fmu, maps, m, method, seed):
    path, fmap = maps(m)
    T_peak = peak_torque(m, fmap)
    rng = np.random.default_rng(seed)
    ops = list(operating_points(rng, T_peak, 1))
    extra = dict(method=method, lut_u_dc=U_DC, lut_T_magnet=T_MAGNET_REF, lut_n_torque=LUT_N, lut_n_speed=LUT_N)
    fresh = run_fresh(controller_fmu, m, path, ops, **extra)
    warm = run_warm(controller_fmu, m, path, ops, rng, T_peak, **extra)
    assert_same(f"{machine_id(m)}, method {method}", fresh, warm, m, T_peak)


# (method, machine id); the tables are built with recursion 2, so its wrong maxima are theirs.
FAIL_TABLES = {(method, m) for method in (2, 3) for m in FAST_FAILING | SLOW_FAILING}


@pytest.mark.parametrize("method", [2, 3])
@pytest.mark.parametrize("m", [pytest.param(m, id=machine_id(m)) for m in FAST])
def test_tables_are_optimal_at_their_nodes(controller_fmu, maps, m, method, request):
    if (method, machine_id(m)) in FAIL_TABLES:
        request.applymarker(_xfail())
    _tables_optimal(controller_fmu, maps, m, method, 30 + method)


@pytest.mark.parametrize("method", [2, 3])
@pytest.mark.parametrize("m", [pytest.param(m, id=machine_id(m)) for m in FAST[:2]])
def test_tables_warm_equals_fresh(controller_fmu, maps, m, method):
    _tables_history(controller_fmu, maps, m, method, 40 + method)


@pytest.mark.slow
@pytest.mark.parametrize("method", [2, 3])
@pytest.mark.parametrize("m", [pytest.param(m, id=machine_id(m)) for m in SLOW])
def test_tables_are_optimal_at_their_nodes_more(controller_fmu, maps, m, method, request):
    if (method, machine_id(m)) in FAIL_TABLES:
        request.applymarker(_xfail())
    _tables_optimal(controller_fmu, maps, m, method, 50 + method)
