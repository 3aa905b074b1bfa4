"""The IpmsmPlant FMU (build/fmu/IpmsmPlant.fmu, plant/) as an FMI 2.0 component: validation, the
contract's variables, the committed modelDescription.xml, consistent initial outputs, refused
maps, inputs and parameters (fmi2Error with a clear log message, the instance stays usable),
CVODE failures with CVODE's message, FMU states and serialisation restoring the solver exactly
(bit-identical outputs after a rollback), reset, and two instances in one process.

The FMU comes from the conftest fixture plant_fmu ($IPMSM_FMU_DIR, default <repo>/build/fmu): a
missing FMU fails the tests.
"""
import math
import struct
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from scenarios.maps.flux_map import linear_flux_map, read_flux_map, write_flux_map

from conftest import ROOT
from fmi2_raw import OK, WARNING, refused

OUTPUTS = ("i_d", "i_q", "psi_d", "psi_q", "T_e", "T_shaft", "P_elec", "P_mech", "P_cu", "P_fe")

# The contract (docs/spec/INTERFACE.md): name -> (causality, type, unit).
CONTRACT = {
    "u_d": ("input", "Real", "V"), "u_q": ("input", "Real", "V"), "w_m": ("input", "Real", "rad/s"),
    "T_magnet": ("input", "Real", "K"), "T_winding": ("input", "Real", "K"),
    "i_d": ("output", "Real", "A"), "i_q": ("output", "Real", "A"),
    "psi_d": ("output", "Real", "Wb"), "psi_q": ("output", "Real", "Wb"),
    "T_e": ("output", "Real", "N.m"), "T_shaft": ("output", "Real", "N.m"),
    "P_elec": ("output", "Real", "W"), "P_mech": ("output", "Real", "W"),
    "P_cu": ("output", "Real", "W"), "P_fe": ("output", "Real", "W"),
    "flux_map": ("parameter", "String", None), "pole_pairs": ("parameter", "Integer", None),
    "R_s": ("parameter", "Real", "Ohm"), "T_winding_ref": ("parameter", "Real", "K"),
    "k_psi_T": ("parameter", "Real", "1/K"), "T_magnet_ref": ("parameter", "Real", "K"),
    "rtol": ("parameter", "Real", None), "atol": ("parameter", "Real", None),
}


def outputs(p):
    return tuple(p.get(*OUTPUTS))


def step(p, h=1e-4):
    """One step that must succeed (fmi2Warning included: leaving the map's grid warns)."""
    status = p.step(h)
    assert status in (OK, WARNING), p.log.text()


def run(p, n, w_m=900.0, h=1e-4, k0=0):
    """n steps of a voltage pattern around the back-EMF; returns the outputs after each."""
    rows = []
    for k in range(k0, k0 + n):
        p.set(w_m=w_m, u_d=-10.0 if (k // 20) % 2 == 0 else -25.0,
              u_q=(8.0 if (k // 20) % 2 == 0 else -4.0) + 0.312 * w_m)
        step(p, h)
        rows.append(outputs(p))
    return rows


def bits(rows):
    return [struct.pack(f"<{len(r)}d", *r) for r in rows]


@pytest.fixture(scope="module")
def md(plant_fmu):
    return read_model_description(str(plant_fmu))


@pytest.fixture
def plants(fmu_instances):
    def make(name="plant"):
        return fmu_instances("IpmsmPlant", name, logging_on=True)

    return make


# --- the FMU as a file -------------------------------------------------------------------------

def test_fmpy_validate(plant_fmu):
    assert validate_fmu(str(plant_fmu)) == []


def test_contract_variables(md):
    vars_ = {v.name: v for v in md.modelVariables}
    for name, (causality, type_, unit) in CONTRACT.items():
        assert name in vars_, f"contract variable {name} missing"
        v = vars_[name]
        assert (v.causality, v.type) == (causality, type_), name
        if unit is not None:
            assert v.unit == unit, name
    assert vars_["w_m"].displayUnit == "rpm"
    assert vars_["T_magnet"].displayUnit == "degC" and vars_["T_winding"].displayUnit == "degC"
    for v in md.modelVariables:
        assert v.description, f"{v.name} has no description"
        if v.type == "Real" and v.name != "fe_k_e":  # W/Hz^2 is not among the glue's units
            assert v.unit, f"{v.name} has no unit"
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate


def test_parameter_defaults_are_the_default_motor(md, default_map_path):
    meta = read_flux_map(default_map_path).metadata
    start = {v.name: v.start for v in md.modelVariables}
    for name, key in [("pole_pairs", "pole_pairs"), ("R_s", "R_s_ohm"), ("T_winding_ref", "T_winding_ref_K"),
                      ("alpha_cu", "alpha_cu_per_K"), ("T_magnet_ref", "T_magnet_ref_K"),
                      ("k_psi_T", "k_psi_T_per_K"), ("fe_k_h", "fe_k_h_W_per_Hz"), ("fe_alpha", "fe_alpha"),
                      ("fe_k_e", "fe_k_e_W_per_Hz2"), ("fe_psi_ref", "fe_psi_ref_Wb")]:
        assert float(start[name]) == pytest.approx(float(meta[key]), rel=1e-12), name
    assert start["flux_map"] in ("", None)


def test_committed_model_description_is_the_generated_one(plant_fmu):
    with zipfile.ZipFile(plant_fmu) as z:
        generated = z.read("modelDescription.xml")
    committed = (ROOT / "plant" / "modelDescription.xml").read_bytes()
    assert committed == generated, ("plant/modelDescription.xml differs from the build's: copy "
                                    "build/fmu/IpmsmPlant/modelDescription.xml over it")


def test_package_carries_default_map_and_documentation(plant_fmu, default_map_path):
    with zipfile.ZipFile(plant_fmu) as z:
        names = set(z.namelist())
        assert z.read("resources/ev_ipmsm_default.csv") == default_map_path.read_bytes()
    assert {"binaries/linux64/IpmsmPlant.so", "documentation/index.html"} <= names


# --- behaviour ----------------------------------------------------------------------------------

def test_initial_outputs_are_consistent(plants, default_map_path):
    psi_m = read_flux_map(default_map_path).psi_m
    p = plants()
    p.init(T_magnet=353.15, T_winding=333.15)
    i_d, i_q, psi_d, psi_q, T_e, T_shaft, P_elec, P_mech, P_cu, P_fe = outputs(p)
    assert psi_d == pytest.approx(psi_m * (1 - 0.0012 * 60), rel=1e-9)
    assert psi_q == 0.0
    assert i_d == 0.0 and i_q == 0.0 and T_e == 0.0  # the start values exactly (issue 12 item 7)
    assert P_fe == 0.0 and T_shaft == T_e
    assert p.get("R_s_T") == pytest.approx(0.012 * (1 + 0.00393 * 40), rel=1e-12)

    q = plants(name="loaded")
    q.init(i_d_start=-200.0, i_q_start=300.0, w_m=600.0)
    i_d, i_q, psi_d, psi_q, T_e, T_shaft, P_elec, P_mech, P_cu, P_fe = outputs(q)
    assert (i_d, i_q) == (-200.0, 300.0)
    assert T_e > 100 and P_fe > 0 and T_shaft == pytest.approx(T_e - P_fe / 600.0, rel=1e-12)
    assert P_mech == pytest.approx(T_shaft * 600.0, rel=1e-12)
    assert P_cu == pytest.approx(1.5 * 0.012 * (200.0**2 + 300.0**2), rel=1e-6)


def test_start_currents_outside_the_grid_are_refused(plants):
    p = plants()
    assert p.setup() == OK
    assert p.enter() == OK
    p.set(i_d_start=-2000.0)
    text = refused(p, p.exit, match="outside the flux map's grid")
    assert "i_d_start = -2000 A" in text
    p.set(i_d_start=-200.0)  # usable, and a start inside the grid loads
    assert p.exit() == OK
    assert p.get("i_d") == -200.0


def test_results_do_not_depend_on_the_start_time(plants):
    """A wall-clock master starting at t = 1.7e9 s gets what one starting at 0 gets (issue 12 item 4:
    the plant integrated one explicit Euler step per step there, 190 A off after 20 ms)."""
    runs = []
    for t0 in (0.0, 1.7e9):
        p = plants(name=f"t0={t0}")
        assert p.setup(start=t0) == OK and p.enter() == OK
        p.set(i_d_start=-100.0, i_q_start=150.0)
        assert p.exit() == OK
        runs.append(np.array(run(p, 400, w_m=1256.6)))
    a, b = runs
    err = np.abs(a - b) / np.maximum(np.abs(a), 1e-300)
    print(f"start time 0 vs 1.7e9 s: largest relative difference {err.max():.2e}")
    assert np.abs(a[:, :2] - a[0, :2]).max() > 10  # the currents moved
    assert np.all(np.abs(a - b) <= 1e-9 * np.abs(a).max(axis=0))


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_nonfinite_inputs_refused_and_instance_stays_usable(plants, value):
    p = plants()
    p.init()
    before = run(p, 5)
    for name in ("u_d", "u_q", "w_m", "T_magnet", "T_winding"):
        refused(p, p.set_status, name, value, match=f"{name} = ")
    after = run(p, 5, k0=5)
    assert np.all(np.isfinite(after)) and bits(before) != bits(after)


@pytest.mark.parametrize("name, value", [("u_d", 1e6), ("w_m", -2e4), ("T_magnet", 5.0), ("T_winding", 1e4)])
def test_absurd_inputs_refused(plants, name, value):
    p = plants()
    p.init()
    refused(p, p.set_status, name, value, match="out of range")


@pytest.mark.parametrize("name, value", [
    ("pole_pairs", 0), ("R_s", -1.0), ("R_s", 1e9), ("rtol", 0.0), ("atol", -1.0), ("fe_psi_ref", 0.0),
    ("k_psi_T", 0.5), ("cvode_method", 3), ("T_magnet_ref", 2000.0), ("cvode_max_steps", 0),
])
def test_absurd_parameters_refused(plants, name, value):
    p = plants()
    assert p.setup() == OK
    assert p.enter() == OK
    refused(p, p.set_status, name, value, match="out of range")
    assert p.exit() == OK  # still the defaults: fine
    assert np.all(np.isfinite(run(p, 3)))


def test_absurd_parameter_combinations_refused_at_initialisation(plants):
    p = plants()
    assert p.setup() == OK
    assert p.enter() == OK
    p.set(cvode_method=2, cvode_max_order=7)
    refused(p, p.exit, match="cvode_max_order")
    p.set(cvode_max_order=5)
    assert p.exit() == OK
    assert np.all(np.isfinite(run(p, 3)))


def _write(path, text):
    path.write_text(text)
    return str(path)


def test_bad_flux_maps_are_refused(plants, tmp_path):
    lin = tmp_path / "linear.csv"
    write_flux_map(lin, linear_flux_map(0.25e-3, 0.6e-3, 0.08, 500.0, 9))
    lines = lin.read_text().splitlines()
    header = lines.index("i_d,i_q,psi_d,psi_q")
    folded = list(lines)
    cells = folded[header + 40].split(",")
    cells[2] = "-1.0"  # psi_d falls with i_d there: not invertible
    folded[header + 40] = ",".join(cells)
    cases = {
        "missing": (str(tmp_path / "nope.csv"), "nope.csv"),
        "empty": (_write(tmp_path / "empty.csv", ""), "empty.csv"),
        "malformed": (_write(tmp_path / "malformed.csv",
                             "\n".join(lines[:header + 3] + ["1,2,abc,4"] + lines[header + 4:])), "malformed.csv"),
        "not a grid": (_write(tmp_path / "holes.csv", "\n".join(lines[:-3])), "holes.csv"),
        "not invertible": (_write(tmp_path / "folded.csv", "\n".join(folded)), "folded.csv"),
        "a directory": (str(tmp_path), str(tmp_path)),
    }
    for what, (path, match) in cases.items():
        p = plants(name=what.replace(" ", "_"))
        assert p.setup() == OK
        assert p.enter() == OK
        p.set(flux_map=path)
        text = refused(p, p.exit, match=match)
        assert "flux map" in text, (what, text)
        # usable after correcting the parameter
        p.set(flux_map=str(lin))
        assert p.exit() == OK
        assert np.all(np.isfinite(run(p, 3)))


def test_measured_non_reciprocal_map_loads(plants, measured_map_path):
    p = plants()
    p.init(flux_map=str(measured_map_path), pole_pairs=2, R_s=0.63, fe_k_h=0.0, fe_k_e=0.0)
    assert p.get("psi_d") == pytest.approx(read_flux_map(measured_map_path).psi_m, rel=1e-9)
    p.set(w_m=150.0, u_d=3.0, u_q=0.15 * 2 * 150 * 0.44)
    for _ in range(20):
        step(p)
    assert np.all(np.isfinite(outputs(p)))
    # the map's metadata (pole_pairs 2, R_s 0.63) agrees with the parameters: no warning about them
    assert "says pole_pairs" not in p.log.text()


def test_map_metadata_disagreeing_with_parameters_is_a_warning(plants, measured_map_path):
    p = plants()
    p.init(flux_map=str(measured_map_path), fe_k_h=0.0, fe_k_e=0.0)  # pole_pairs 4, R_s 0.012
    assert "says pole_pairs: 2, but the parameter pole_pairs is 4" in p.log.text()


def test_cvode_failure_is_fmi2error_with_cvodes_message(plants):
    p = plants()
    p.init()
    run(p, 3)
    before = outputs(p)
    # rtol, atol at their floor: more than one internal step even for the small remainder of the
    # step's linearisation that CVODE integrates
    p.set(cvode_max_steps=1, rtol=1e-14, atol=1e-15, u_q=500.0, w_m=1256.6)
    text = refused(p, p.step, match="mxstep steps taken before reaching tout")
    assert "CVODE" in text and "CV_TOO_MUCH_WORK" in text
    assert outputs(p) == before  # undone
    p.set(cvode_max_steps=20000, rtol=1e-6, atol=1e-6)
    step(p)
    assert np.all(np.isfinite(outputs(p)))


def test_get_set_fmu_state_is_bit_identical(plants):
    p = plants()
    p.init()
    run(p, 30, w_m=1256.6)
    s = p.get_state()
    t = p.t
    a = run(p, 50, w_m=1256.6, k0=30)
    assert p.set_state(s) == OK
    p.t = t
    b = run(p, 50, w_m=1256.6, k0=30)
    assert bits(a) == bits(b)
    assert p.free_state(s) == OK


def test_serialised_state_into_a_fresh_instance_is_bit_identical(plants):
    p = plants()
    p.init(rtol=1e-7)
    run(p, 30, w_m=700.0)
    s = p.get_state()
    data = p.serialize(s)
    assert p.free_state(s) == OK
    t = p.t
    a = run(p, 60, w_m=700.0, k0=30)

    q = plants(name="fresh")  # not initialised; same fixed parameter (rtol is tunable anyway)
    assert q.setup() == OK
    status, s2 = q.deserialize_status(data)
    assert status == OK, q.log.text()
    assert q.set_state(s2) == OK
    q.t = t
    assert q.get("rtol") == 1e-7
    b = run(q, 60, w_m=700.0, k0=30)
    assert bits(a) == bits(b)
    assert q.free_state(s2) == OK


def test_reset_then_run_again_reproduces(plants):
    p = plants()
    p.init()
    a = run(p, 40, w_m=1256.6)
    assert p.reset() == OK
    p.init()
    b = run(p, 40, w_m=1256.6)
    assert bits(a) == bits(b)
    assert p.terminate() == OK


def test_two_instances_interleaved_are_identical(plants):
    a, b = plants(name="a"), plants(name="b")
    a.init(T_magnet=340.0)
    b.init(T_magnet=340.0)
    ra, rb = [], []
    for k in range(60):
        ra += run(a, 1, w_m=1000.0, k0=k)
        rb += run(b, 1, w_m=1000.0, k0=k)
    assert bits(ra) == bits(rb)


def test_variable_step_sizes_and_tiny_steps(plants):
    p = plants()
    p.init()
    p.set(w_m=500.0, u_d=-20.0, u_q=0.312 * 500.0)
    for h in (1e-4, 1e-3, 1e-6, 1e-12, 3e-5):
        step(p, h)
        assert np.all(np.isfinite(outputs(p)))
    assert p.get("cvode_steps") >= 1


def test_currents_leaving_the_map_warn_once(plants):
    p = plants()
    p.init()
    p.set(w_m=0.0, u_d=-40.0, u_q=0.0)  # drives i_d below the grid's -700 A
    for _ in range(100):
        step(p)
    warnings = [m for s, c, m in p.log.records if c == "logStatusWarning" and "left the flux map" in m]
    assert len(warnings) == 1, p.log.text()
    assert p.get("i_d") < -700
