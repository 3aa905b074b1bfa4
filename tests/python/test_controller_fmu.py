"""The IpmsmController FMU as an importer sees it: model description, simulation with fmpy,
bad input (clear error, instance stays usable), FMU state round trips, several instances."""
from __future__ import annotations

import math
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from scenarios.core.constants import U_DC_NOMINAL_V

from conftest import ROOT
from fmi2_raw import ERROR, OK, refused

CONTRACT = ["T_ref", "w_m", "u_dc", "i_d", "i_q", "T_magnet", "i_d_ref", "i_q_ref", "u_d_ref", "u_q_ref",
            "T_cmd", "T_max", "T_est", "region", "iterations", "method", "recursion", "flux_map", "pole_pairs",
            "R_s", "I_max", "k_u", "T_magnet_ref", "k_psi_T", "lut_u_dc", "lut_T_magnet"]
OUTPUTS = ["i_d_ref", "i_q_ref", "u_d_ref", "u_q_ref", "T_cmd", "T_max", "T_est", "region", "iterations"]
H = 1e-4


def test_validates_with_fmpy(controller_fmu):
    problems = validate_fmu(str(controller_fmu))
    assert problems == [], problems


def test_contract_variables_and_units(controller_fmu):
    md = read_model_description(str(controller_fmu))
    v = {x.name: x for x in md.modelVariables}
    missing = [n for n in CONTRACT if n not in v]
    assert not missing, missing
    assert v["T_ref"].unit == "N.m" and v["w_m"].unit == "rad/s" and v["u_dc"].unit == "V"
    assert v["T_magnet"].unit == "K" and v["R_s"].unit == "Ohm" and v["k_psi_T"].unit == "1/K"
    assert v["region"].type == "Integer" and v["flux_map"].type == "String"
    assert all(x.description for x in md.modelVariables)
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate


def test_committed_model_description_is_the_generated_one(controller_fmu):
    """The top-level modelDescription.xml (the controller's) is generated from the C++ table."""
    with zipfile.ZipFile(controller_fmu) as z:
        generated = z.read("modelDescription.xml").decode()
    committed = (ROOT / "modelDescription.xml").read_text()
    assert committed == generated, "regenerate: cp build/fmu/IpmsmController/modelDescription.xml ."


def test_simulates_with_fmpy(controller_fmu):
    """fmpy's own master: a torque ramp at 3000 r/min, no plant (measured currents zero)."""
    t = np.linspace(0, 0.02, 5)
    inputs = np.array([(ti, 300.0 * ti / 0.02) for ti in t], dtype=[("time", float), ("T_ref", float)])
    r = simulate_fmu(str(controller_fmu), stop_time=0.02, step_size=H, input=inputs,
                     start_values={"w_m": 3000 * math.pi / 30},
                     output=["T_cmd", "T_max", "i_d_ref", "i_q_ref", "region"])
    assert np.all(np.isfinite(r["i_q_ref"]))
    assert r["T_cmd"][-1] == pytest.approx(min(300.0, r["T_max"][-1]), rel=1e-9)
    assert r["T_max"][-1] == pytest.approx(285.36, rel=2e-3)  # the default motor's peak
    assert set(r["region"]) <= {0, 1}


@pytest.fixture
def controllers(fmu_instances):
    """controllers(name="controller", **parameters): an initialised IpmsmController instance."""

    def make(name="controller", **parameters):
        c = fmu_instances("IpmsmController", name)
        c.init(**parameters)
        return c

    return make


def _step(c, k, **inputs):
    c.set(**inputs)
    status = c.step(H, t=k * H)
    assert status == OK, c.log.text()
    return c.get(*OUTPUTS)


def test_bad_inputs_give_errors_and_the_instance_stays_usable(controllers):
    c = controllers()
    good = _step(c, 0, T_ref=100.0, w_m=300.0, u_dc=U_DC_NOMINAL_V)
    for name, bad in [("T_ref", math.nan), ("w_m", math.inf), ("i_d", -math.inf), ("u_dc", 0.0), ("u_dc", -10.0),
                      ("T_magnet", math.nan), ("T_magnet", 5000.0)]:
        refused(c, c.set_status, name, bad)
    # The bad values were refused: the same inputs give the same outputs.
    assert c.get("T_ref", "w_m", "u_dc") == [100.0, 300.0, U_DC_NOMINAL_V]
    again = _step(c, 1)
    assert np.all(np.isfinite(again[:7]))
    assert again[4] == pytest.approx(good[4])
    refused(c, c.set_status, "method", 2)  # a fixed parameter after initialisation


@pytest.mark.parametrize("params", [dict(method=7), dict(recursion=3), dict(I_max=0.0), dict(I_max=-5.0),
                                    dict(pole_pairs=0), dict(k_u=1.5)])
def test_bad_parameters_are_refused(fmu_instances, params):
    """fmi2Error when set in Initialization Mode, or at the latest when leaving it."""
    c = fmu_instances("IpmsmController")
    assert c.setup() == OK and c.enter() == OK
    (name, value), = params.items()
    status = c.set_status(name, value)
    if status == OK:
        status = c.exit()
    assert status == ERROR, c.log.text()


@pytest.mark.parametrize("content", ["", "i_d,i_q,psi_d,psi_q\n", "# only a comment\n",
                                     "i_d,i_q,psi_d,psi_q\n0,0,0.1,0\n0,1,0.1,0.1\n1,0,0.2,0\n",
                                     "i_d,i_q,psi_d,psi_q\n0,0,abc,0\n"])
def test_bad_flux_map_is_an_error_then_a_good_one_works(fmu_instances, tmp_path, content):
    bad = tmp_path / "bad.csv"
    bad.write_text(content)
    c = fmu_instances("IpmsmController")
    assert c.setup() == OK and c.enter() == OK
    for path in (str(bad), str(tmp_path / "missing.csv")):
        c.set(flux_map=path)
        refused(c, c.exit)
    c.set(flux_map="")  # back to the default map
    assert c.exit() == OK, c.log.text()
    c.set(T_ref=100.0, w_m=100.0)
    assert c.step(H) == OK
    assert c.get("T_cmd") == pytest.approx(100.0)


def _drive(c, k0, n, seed):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(k0, k0 + n):
        out.append(_step(c, k, T_ref=float(rng.uniform(-300, 300)), w_m=float(rng.uniform(-1200, 1200)),
                         i_d=float(rng.uniform(-300, 0)), i_q=float(rng.uniform(-300, 300))))
    return out


@pytest.mark.parametrize("method", [1, 2, 3])
def test_state_rollback_and_serialisation_are_bit_identical(controllers, method):
    c = controllers(method=method)
    _drive(c, 0, 20, 1)
    state = c.get_state()
    blob = c.serialize(state)
    first = _drive(c, 20, 30, 2)
    assert c.set_state(state) == OK
    assert _drive(c, 20, 30, 2) == first
    status, restored = c.deserialize_status(blob)
    assert status == OK, c.log.text()
    assert c.set_state(restored) == OK
    assert _drive(c, 20, 30, 2) == first
    assert c.free_state(state) == OK
    assert c.free_state(restored) == OK


def test_two_instances_and_reset_give_identical_results(controllers):
    a, b = controllers("a"), controllers("b")
    ra, rb = [], []
    rng = np.random.default_rng(5)
    for k in range(50):  # interleaved
        ops = dict(T_ref=float(rng.uniform(-300, 300)), w_m=float(rng.uniform(-1200, 1200)))
        ra.append(_step(a, k, **ops))
        rb.append(_step(b, k, **ops))
    assert ra == rb


@pytest.mark.parametrize("method", [2, 3])
def test_tables_track_the_exact_solver_at_nominal_conditions(controllers, method):
    """The 2-D tables (built for 355 V, 20 degC) against Ferrari at those conditions."""
    rng = np.random.default_rng(method)
    ops = [dict(T_ref=float(rng.uniform(-280, 280)), w_m=float(rng.uniform(-1250, 1250))) for _ in range(300)]
    exact, table = controllers("exact", method=1), controllers("table", method=method)
    err = []
    for k, op in enumerate(ops):
        e = _step(exact, k, **op)
        t = _step(table, k, **op)
        err.append(math.hypot(e[0] - t[0], e[1] - t[1]))
    assert table.get("table_bytes") > 20000
    print(f"\n[method {method}] current command difference vs exact: median {np.median(err):.2f} A, "
          f"99th pct {np.percentile(err, 99):.2f} A, max {max(err):.2f} A")
    assert np.median(err) < 5.0


def test_reset_then_run_again_reproduces_the_first_run(controllers):
    c = controllers(method=1, recursion=1)
    first = _drive(c, 0, 40, 9)
    for _ in range(2):  # double reset is fine
        assert c.reset() == OK
    c.init(method=1, recursion=1)
    assert _drive(c, 0, 40, 9) == first
