"""The IpmsmController FMU as an importer sees it: model description, simulation with fmpy,
bad input (clear error, instance stays usable), FMU state round trips, several instances."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from scenarios.fmu import Fmu

ROOT = Path(__file__).resolve().parents[2]
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
    import zipfile
    with zipfile.ZipFile(controller_fmu) as z:
        generated = z.read("modelDescription.xml").decode()
    committed = (ROOT / "modelDescription.xml").read_text()
    assert committed == generated, "regenerate: cp build/fmu/IpmsmController/modelDescription.xml ."


def test_simulates_with_fmpy(controller_fmu):
    """fmpy's own master: a torque ramp at 3000 r/min, no plant (measured currents zero)."""
    t = np.linspace(0, 0.02, 5)
    inputs = np.array([(ti, 300.0 * ti / 0.02) for ti in t], dtype=[("time", float), ("T_ref", float)])
    r = simulate_fmu(str(controller_fmu), stop_time=0.02, step_size=H, input=inputs,
                     start_values={"w_m": 3000 * math.pi / 30}, output=["T_cmd", "T_max", "i_d_ref", "i_q_ref", "region"])
    assert np.all(np.isfinite(r["i_q_ref"]))
    assert r["T_cmd"][-1] == pytest.approx(min(300.0, r["T_max"][-1]), rel=1e-9)
    assert r["T_max"][-1] == pytest.approx(285.36, rel=2e-3)  # the default motor's peak
    assert set(r["region"]) <= {0, 1}


def _step(c, k, **inputs):
    c.set(**inputs)
    c.step(k * H, H)
    return c.get(*OUTPUTS)


def test_bad_inputs_give_errors_and_the_instance_stays_usable(controller_fmu):
    with Fmu(controller_fmu) as c:
        good = _step(c, 0, T_ref=100.0, w_m=300.0, u_dc=355.0)
        for name, bad in [("T_ref", math.nan), ("w_m", math.inf), ("i_d", -math.inf), ("u_dc", 0.0), ("u_dc", -10.0),
                          ("T_magnet", math.nan), ("T_magnet", 5000.0)]:
            with pytest.raises(FMICallException):
                c.set(**{name: bad})
        # The bad values were refused: the same inputs give the same outputs.
        assert c.get("T_ref", "w_m", "u_dc") == [100.0, 300.0, 355.0]
        again = _step(c, 1)
        assert np.all(np.isfinite(again[:7]))
        assert again[4] == pytest.approx(good[4])
        with pytest.raises(FMICallException):
            c.set(method=2)  # a fixed parameter after initialisation


@pytest.mark.parametrize("params", [dict(method=7), dict(recursion=3), dict(I_max=0.0), dict(I_max=-5.0),
                                    dict(pole_pairs=0), dict(k_u=1.5)])
def test_bad_parameters_are_refused(controller_fmu, params):
    with pytest.raises(FMICallException):
        Fmu(controller_fmu, **params)


@pytest.mark.parametrize("content", ["", "i_d,i_q,psi_d,psi_q\n", "# only a comment\n",
                                     "i_d,i_q,psi_d,psi_q\n0,0,0.1,0\n0,1,0.1,0.1\n1,0,0.2,0\n",
                                     "i_d,i_q,psi_d,psi_q\n0,0,abc,0\n"])
def test_bad_flux_map_is_an_error_then_a_good_one_works(controller_fmu, tmp_path, content):
    from fmpy import extract
    from fmpy.fmi2 import FMU2Slave
    bad = tmp_path / "bad.csv"
    bad.write_text(content)
    md = read_model_description(str(controller_fmu))
    d = extract(str(controller_fmu))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0)
        fmu.enterInitializationMode()
        for path in (str(bad), str(tmp_path / "missing.csv")):
            fmu.setString([vr["flux_map"]], [path])
            with pytest.raises(FMICallException):
                fmu.exitInitializationMode()
        fmu.setString([vr["flux_map"]], [""])  # back to the default map
        fmu.exitInitializationMode()
        fmu.setReal([vr["T_ref"], vr["w_m"]], [100.0, 100.0])
        fmu.doStep(0.0, H)
        assert fmu.getReal([vr["T_cmd"]])[0] == pytest.approx(100.0)
    finally:
        fmu.freeInstance()


def _drive(c, k0, n, seed):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(k0, k0 + n):
        out.append(_step(c, k, T_ref=float(rng.uniform(-300, 300)), w_m=float(rng.uniform(-1200, 1200)),
                         i_d=float(rng.uniform(-300, 0)), i_q=float(rng.uniform(-300, 300))))
    return out


@pytest.mark.parametrize("method", [1, 2, 3])
def test_state_rollback_and_serialisation_are_bit_identical(controller_fmu, method):
    with Fmu(controller_fmu, method=method) as c:
        _drive(c, 0, 20, 1)
        state = c.fmu.getFMUstate()
        blob = c.fmu.serializeFMUstate(state)
        first = _drive(c, 20, 30, 2)
        c.fmu.setFMUstate(state)
        assert _drive(c, 20, 30, 2) == first
        restored = c.fmu.deSerializeFMUstate(blob)
        c.fmu.setFMUstate(restored)
        assert _drive(c, 20, 30, 2) == first
        c.fmu.freeFMUstate(state)
        c.fmu.freeFMUstate(restored)


def test_two_instances_and_reset_give_identical_results(controller_fmu):
    with Fmu(controller_fmu, instance_name="a") as a, Fmu(controller_fmu, instance_name="b") as b:
        ra, rb = [], []
        rng = np.random.default_rng(5)
        for k in range(50):  # interleaved
            ops = dict(T_ref=float(rng.uniform(-300, 300)), w_m=float(rng.uniform(-1200, 1200)))
            ra.append(_step(a, k, **ops))
            rb.append(_step(b, k, **ops))
        assert ra == rb


@pytest.mark.parametrize("method", [2, 3])
def test_tables_track_the_exact_solver_at_nominal_conditions(controller_fmu, method):
    """The 2-D tables (built for 355 V, 20 degC) against Ferrari at those conditions."""
    rng = np.random.default_rng(method)
    ops = [dict(T_ref=float(rng.uniform(-280, 280)), w_m=float(rng.uniform(-1250, 1250))) for _ in range(300)]
    with Fmu(controller_fmu, method=1) as exact, Fmu(controller_fmu, method=method) as table:
        err = []
        for k, op in enumerate(ops):
            e = _step(exact, k, **op)
            t = _step(table, k, **op)
            err.append(math.hypot(e[0] - t[0], e[1] - t[1]))
        assert table.get("table_bytes") > 20000
    print(f"\n[method {method}] current command difference vs exact: median {np.median(err):.2f} A, "
          f"99th pct {np.percentile(err, 99):.2f} A, max {max(err):.2f} A")
    assert np.median(err) < 5.0


def test_reset_then_run_again_reproduces_the_first_run(controller_fmu):
    with Fmu(controller_fmu, method=1, recursion=1) as c:
        first = _drive(c, 0, 40, 9)
        for _ in range(2):  # double reset is fine
            c.fmu.reset()
        c.fmu.setupExperiment(startTime=0.0)
        c.fmu.enterInitializationMode()
        c.set(method=1, recursion=1)
        c.fmu.exitInitializationMode()
        assert _drive(c, 0, 40, 9) == first
