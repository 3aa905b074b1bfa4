"""Hostile input never costs a crash or silent garbage (issue 5), for both FMUs, through the raw
C API (fmi2_raw.py): FMI call-sequence misuse, NULL pointers, wrong value references, odd
resource locations and loggers, non-finite and absurd inputs, hostile step sizes, broken flux
maps, FMU states (round trips bit-identical, corrupted ones refused), instances in threads, and a
seeded random-call-sequence fuzz of the C API (tests/cpp/fmu_fuzz.cpp), also under valgrind.

"Fails cleanly" means: the call returns fmi2Error (logged with the reason), changes nothing (the
instance reads and then steps exactly as an untouched twin), and the instance stays usable.
"""
from __future__ import annotations

import ctypes as C
import math
import os
import shutil
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest

from scenarios.core.constants import U_DC_NOMINAL_V
from scenarios.maps.flux_map import linear_flux_map, write_flux_map

import fmi2_raw as raw
from conftest import BUILD_FMU, same
from fmi2_raw import ERROR, OK, WARNING

FMUS = ["IpmsmController", "IpmsmPlant"]
# inputs of a normal operating point
NORMAL = {
    "IpmsmController": dict(T_ref=100.0, w_m=300.0, u_dc=U_DC_NOMINAL_V, i_d=-50.0, i_q=150.0, T_magnet=330.0),
    "IpmsmPlant": dict(u_d=-20.0, u_q=60.0, w_m=300.0, T_magnet=330.0, T_winding=350.0),
}
FUZZ_BIN = BUILD_FMU.parent / "bin" / "fmu_fuzz"
FUZZ_SKIP = ["--skip", "lut_n_torque", "--skip", "lut_n_speed"]  # a 1001 x 1001 table takes minutes to build


def run(inst, n, inputs, k0=0):
    """n steps with `inputs` (dict, or callable k -> dict); the outputs after each."""
    rows = []
    for k in range(k0, k0 + n):
        inst.set(**(inputs(k) if callable(inputs) else inputs))
        status = inst.step()
        assert status in (OK, WARNING), f"step {k}: {raw.STATUS[status]}\n{inst.log.text()}"
        rows.append(inst.outputs())
    return rows


def twins(make, name, **params):
    a, b = make(name), make(name)
    a.init(**params)
    b.init(**params)
    return a, b


def varying(name):
    base = NORMAL[name]
    return lambda k: {n: v * (1 + 0.1 * math.sin(0.3 * k + i)) for i, (n, v) in enumerate(base.items())}


# --- FMI call-sequence misuse ---

@pytest.mark.parametrize("name", FMUS)
def test_do_step_before_initialisation(make, name):
    a, ref = make(name), make(name)
    assert a.step() == ERROR  # instantiated
    assert "fmi2DoStep is not allowed in state instantiated" in a.log.text()
    assert a.setup() == OK and a.enter() == OK
    assert a.step() == ERROR  # initializationMode
    assert a.exit() == OK
    ref.init()
    assert same(run(a, 5, NORMAL[name]), run(ref, 5, NORMAL[name]))


@pytest.mark.parametrize("name", FMUS)
def test_parameters_after_initialisation(make, name):
    a, ref = twins(make, name)
    run(a, 3, NORMAL[name]), run(ref, 3, NORMAL[name])
    for v in a.fmu.md.modelVariables:
        if v.causality != "parameter":
            continue
        value = a.get(v.name)
        other = {"Real": lambda x: x * 1.5 + 1.0, "Integer": lambda x: x + 1,
                 "String": lambda x: x + "x", "Boolean": lambda x: not x}[v.type](value)
        status = a.set_status(v.name, other)
        if v.variability == "fixed":
            assert status == ERROR, v.name
            assert a.get(v.name) == value
            assert "is a fixed parameter" in a.log.text()
        else:  # tunable: a new value within its range is accepted; then put back
            assert status == OK or (status == ERROR and "out of range" in a.log.text()), v.name
            assert a.set_status(v.name, value * 1.001 if v.type == "Real" else value) == OK
            assert a.set_status(v.name, value) == OK
    assert same(run(a, 5, NORMAL[name], 3), run(ref, 5, NORMAL[name], 3))


@pytest.mark.parametrize("name", FMUS)
def test_wrong_value_references_change_nothing(make, name):
    a, ref = twins(make, name)
    n = len(a.fmu.md.modelVariables)
    first_input = next(v for v in a.fmu.md.modelVariables if v.causality == "input" and v.type == "Real")
    integer_vr = next(v.valueReference for v in a.fmu.md.modelVariables if v.type == "Integer")
    for bad in (n, n + 100, 2**32 - 1):
        refs = raw.vrs([first_input.valueReference, bad])  # a valid one first: all or nothing
        assert a.fmu.fmi2SetReal(a.c, refs, 2, raw.reals([123.0, 1.0])) == ERROR
        assert a.fmu.fmi2GetReal(a.c, refs, 2, raw.reals([0.0, 0.0])) == ERROR
        assert "unknown value reference" in a.log.text()
    assert a.get(first_input.name) == float(first_input.start)
    refs = raw.vrs([integer_vr])
    assert a.fmu.fmi2GetReal(a.c, refs, 1, raw.reals([0.0])) == ERROR  # an Integer read as a Real
    assert a.fmu.fmi2SetReal(a.c, refs, 1, raw.reals([1.0])) == ERROR
    assert a.fmu.fmi2GetBoolean(a.c, raw.vrs([first_input.valueReference]), 1, raw.ints([0])) == ERROR
    assert same(run(a, 5, NORMAL[name]), run(ref, 5, NORMAL[name]))


@pytest.mark.parametrize("name", FMUS)
def test_null_pointers_and_zero_lengths(make, unzipped, name):
    f = unzipped(name)
    a, ref = twins(make, name)
    null = None
    vr = raw.vrs([0])
    # zero-length arrays, NULL or not: nothing to do
    for fn, values in ((f.fmi2GetReal, raw.reals([0.0])), (f.fmi2SetReal, raw.reals([0.0])),
                       (f.fmi2GetInteger, raw.ints([0])), (f.fmi2SetInteger, raw.ints([0])),
                       (f.fmi2GetBoolean, raw.ints([0])), (f.fmi2SetBoolean, raw.ints([0]))):
        assert fn(a.c, null, 0, null) == OK
        assert fn(a.c, vr, 0, values) == OK
    assert f.fmi2GetString(a.c, null, 0, null) == OK and f.fmi2SetString(a.c, null, 0, null) == OK
    # NULL arrays with n > 0
    for fn, values in ((f.fmi2GetReal, raw.reals([0.0])), (f.fmi2SetReal, raw.reals([0.0])),
                       (f.fmi2GetInteger, raw.ints([0])), (f.fmi2SetInteger, raw.ints([0]))):
        assert fn(a.c, null, 1, values) == ERROR
        assert fn(a.c, vr, 1, null) == ERROR
    assert f.fmi2GetString(a.c, vr, 1, null) == ERROR and f.fmi2SetString(a.c, null, 1, null) == ERROR
    string_vr = raw.vrs([f.vars["flux_map"].valueReference])
    assert f.fmi2SetString(a.c, string_vr, 1, (C.c_char_p * 1)(None)) == ERROR  # a NULL string
    # NULL out-pointers of the state and status functions
    assert f.fmi2GetFMUstate(a.c, null) == ERROR
    assert f.fmi2SetFMUstate(a.c, null) == ERROR
    assert f.fmi2FreeFMUstate(a.c, null) == OK  # nothing to free
    assert f.fmi2SerializedFMUstateSize(a.c, null, null) == ERROR
    assert f.fmi2SerializeFMUstate(a.c, null, null, 0) == ERROR
    assert f.fmi2DeSerializeFMUstate(a.c, null, 0, null) == ERROR
    assert f.fmi2DeSerializeFMUstate(a.c, null, 16, C.byref(C.c_void_p())) == ERROR
    for fn in (f.fmi2GetStatus, f.fmi2GetRealStatus, f.fmi2GetIntegerStatus, f.fmi2GetBooleanStatus,
               f.fmi2GetStringStatus):
        assert fn(a.c, raw.KIND_DO_STEP, null) == ERROR
    assert f.fmi2SetDebugLogging(a.c, 1, 2, null) == ERROR
    assert f.fmi2GetDirectionalDerivative(a.c, null, 0, null, 0, null, null) == ERROR
    assert f.fmi2SetRealInputDerivatives(a.c, null, 0, null, null) == ERROR
    assert f.fmi2GetRealOutputDerivatives(a.c, null, 0, null, null) == ERROR
    # a NULL instance: refused by every function, no crash
    for fn_name, (restype, argtypes) in raw.SIGNATURES.items():
        if not argtypes or argtypes[0] is not raw.comp:
            continue
        args = [None] + [0 if t in (C.c_int, C.c_size_t, C.c_double) else None for t in argtypes[1:]]
        result = getattr(f, fn_name)(*args)
        if restype is not None:
            assert result == ERROR, fn_name
    # instantiate with NULL strings
    assert not f.fmi2Instantiate(None, raw.CO_SIMULATION, f.guid.encode(), None, None, 0, 0)
    assert not f.fmi2Instantiate(b"x", raw.CO_SIMULATION, None, None, None, 0, 0)
    assert not f.fmi2Instantiate(b"", raw.CO_SIMULATION, f.guid.encode(), None, None, 0, 0)
    assert not f.fmi2Instantiate(b"x", raw.MODEL_EXCHANGE, f.guid.encode(), None, None, 0, 0)
    assert not f.fmi2Instantiate(b"x", 77, f.guid.encode(), None, None, 0, 0)
    assert same(run(a, 5, NORMAL[name]), run(ref, 5, NORMAL[name]))


@pytest.mark.parametrize("name", FMUS)
@pytest.mark.parametrize("where", ["instantiated", "initializationMode", "stepComplete with states", "terminated",
                                   "after an error"])
def test_free_instance_without_terminate(make, name, where):
    a = make(name)
    if where != "instantiated":
        assert a.setup() == OK and a.enter() == OK
    if where in ("stepComplete with states", "terminated", "after an error"):
        assert a.exit() == OK
        run(a, 3, NORMAL[name])
        a.get_state()
        s = a.get_state()
        a.serialize(s)
    if where == "terminated":
        assert a.terminate() == OK
    if where == "after an error":
        assert a.step(h=-1.0) == ERROR
        assert a.set_status("w_m", math.nan) == ERROR
    a.free()  # with FMU states alive: the FMU frees them (valgrind and ASan check that)


@pytest.mark.parametrize("name", FMUS)
def test_double_reset_then_again(make, name):
    a, ref = make(name), make(name)
    a.init()
    first = run(a, 10, varying(name))
    assert a.reset() == OK and a.reset() == OK
    assert a.step() == ERROR  # instantiated again
    a.init()
    assert same(run(a, 10, varying(name)), first)
    ref.init()
    assert same(run(ref, 10, varying(name)), first)
    assert a.terminate() == OK and a.reset() == OK and a.reset() == OK


@pytest.mark.parametrize("name", FMUS)
@pytest.mark.parametrize("callbacks", ["NULL logger", "NULL callbacks"])
def test_null_logger(make, unzipped, name, callbacks):
    f = unzipped(name)
    if callbacks == "NULL logger":
        a = make(name, logger=raw.Logger(with_logger=False), logging_on=True)
    else:
        a = make(name, logger=None, logging_on=True)
    a.init()
    assert f.fmi2SetDebugLogging(a.c, 1, 0, None) == OK
    assert a.step(h=0.0) == ERROR and a.set_status("w_m", math.inf) == ERROR  # errors, nobody to tell
    assert a.set_status("flux_map", "x") == ERROR  # fixed
    ref = make(name)
    ref.init()
    assert same(run(a, 5, NORMAL[name]), run(ref, 5, NORMAL[name]))
    if a.log is not None:
        assert a.log.memory_calls == 0


@pytest.mark.parametrize("name", FMUS)
def test_null_resource_location(make, unzipped, name):
    a = make(name, resource_uri=None)
    assert "is not a local file URI" in a.log.text() or a.log.records == []  # warned (if logging)
    assert a.setup() == OK and a.enter() == OK
    assert a.exit() == ERROR
    assert "resources/ folder is unknown" in a.log.text()
    a.set(flux_map=str(unzipped(name).dir / "resources" / "ev_ipmsm_default.csv"))
    assert a.exit() == OK
    ref = make(name)
    ref.init()
    assert same(run(a, 5, NORMAL[name]), run(ref, 5, NORMAL[name]))


@pytest.mark.parametrize("name", FMUS)
def test_percent_encoded_resource_location(make, unzipped, tmp_path, name):
    odd = unzipped(name).copy_to(tmp_path / "a dir with spaces, 100% ü & #hash" / name)
    uri = raw.resource_uri_of(odd / "resources")
    assert "%20" in uri and "%25" in uri and "%C3%BC" in uri
    a = make(name, resource_uri=uri, logging_on=True)
    a.init()
    assert str(odd / "resources") in a.log.text()
    ref = make(name)
    ref.init()
    assert same(run(a, 5, NORMAL[name]), run(ref, 5, NORMAL[name]))
    for bad in ("file://otherhost/x", "file:///bad%zzescape", "relative/path", "http://example.invalid/r", ""):
        b = make(name, resource_uri=bad)
        assert b.setup() == OK and b.enter() == OK and b.exit() == ERROR  # no resources: no default map


# --- hostile inputs ---

HOSTILE_VALUES = [math.nan, math.inf, -math.inf, 1e300, -1e300, 1e30, -1e30, 5e-324, -0.0]


@pytest.mark.parametrize("name", FMUS)
@pytest.mark.parametrize("value", HOSTILE_VALUES, ids=repr)
def test_hostile_input_values_fail_cleanly(make, name, value):
    """Every input, every hostile value: refused (and nothing changed) or accepted, and then the
    step either gives finite outputs or fails and changes nothing; the instance stays usable."""
    for inp in NORMAL[name]:
        a, ref = twins(make, name)
        run(a, 2, NORMAL[name]), run(ref, 2, NORMAL[name])
        status = a.set_status(inp, value)
        if not math.isfinite(value):
            assert status == ERROR and "not a finite number" in a.log.text(), (inp, value)
        if status == ERROR:
            assert a.get(inp) == NORMAL[name][inp]
            assert a.outputs() == ref.outputs()
        else:
            assert status == OK and a.get(inp) == value
            before = a.outputs()
            step = a.step()
            assert step in (OK, WARNING, ERROR), (inp, value, step)
            if step == ERROR:
                assert repr(a.outputs()) == repr(before), "a failed step changed the outputs"
                assert "was undone" in a.log.text()
            else:
                assert all(math.isfinite(x) for x in a.outputs()), (inp, value, a.outputs())
        # usable again: back to normal inputs, it steps like a fresh instance does
        a.set(**NORMAL[name])
        assert a.step() in (OK, WARNING) and all(math.isfinite(x) for x in a.outputs()), a.log.text()


def test_u_dc_must_be_positive(make):
    a, ref = twins(make, "IpmsmController")
    for bad in (0.0, -0.0, -355.0, -1e-300):
        assert a.set_status("u_dc", bad) == ERROR
        assert "u_dc" in a.log.text() and "out of range" in a.log.text()
    assert same(run(a, 5, NORMAL["IpmsmController"]), run(ref, 5, NORMAL["IpmsmController"]))
    # a tiny positive DC voltage: no voltage, so no torque above standstill; finite outputs
    a.set(u_dc=1e-3, T_ref=200.0, w_m=300.0)
    assert a.step() in (OK, WARNING)
    out = dict(zip(a.names("output"), a.outputs()))
    assert all(math.isfinite(x) for x in out.values())
    assert abs(out["T_cmd"]) <= abs(out["T_max"]) + 1e-9
    assert math.hypot(out["u_d_ref"], out["u_q_ref"]) <= 1e-3 / math.sqrt(3) * (1 + 1e-9)


@pytest.mark.parametrize("name", FMUS)
def test_zero_and_reversing_speed(make, name):
    a = make(name)
    a.init()
    speeds = [0.0] * 5 + [300.0, -300.0] * 5 + list(np.linspace(600, -600, 41)) + [0.0, -0.0, 1e-300, -1e-300]
    for w in speeds:
        a.set(**{**NORMAL[name], "w_m": float(w)})
        assert a.step() in (OK, WARNING), a.log.text()
        assert all(math.isfinite(x) for x in a.outputs()), (w, a.outputs())


def test_coupled_drive_through_zero_speed(controller_fmu, plant_fmu):
    """Controller and plant, a motoring torque while the speed reverses from +3000 to -3000 r/min:
    the drive stays within the current limit and follows the command through standstill."""
    from scenarios.cosim.reference import ReferenceDrive
    n = 400

    def w(k):
        return (3000 - 6000 * k / n) * math.pi / 30

    rows = []
    # the reference loop: every FMI call from Python, on whatever build the FMUs come from (ASan too)
    with ReferenceDrive(controller_fmu, plant_fmu, w_m=w(0)) as ref:
        for k in range(n):
            e = ref.advance(1e-4, 150.0, w(k), 355.0, 293.15, 293.15)
            rows.append((e.T_cmd, e.T_e, math.hypot(e.i_d, e.i_q)))
    r = np.array(rows)
    assert np.all(np.isfinite(r))
    assert np.max(r[:, 2]) < 500 * 1.05
    settled = r[50:]
    assert np.max(np.abs(settled[:, 1] - settled[:, 0])) < 0.05 * 150


@pytest.mark.parametrize("rpm", [0.0, 3000.0, -3000.0, 11000.0, 20000.0, -20000.0, 1e6])
@pytest.mark.parametrize("T_ref", [1e4, -1e4, 1e9, -1e300])
def test_torque_far_beyond_reach_is_clamped(make, rpm, T_ref):
    a = make("IpmsmController")
    a.init()
    w = rpm * math.pi / 30
    a.set(T_ref=T_ref, w_m=w)
    assert a.step() in (OK, WARNING), a.log.text()
    out = dict(zip(a.names("output"), a.outputs()))
    assert all(math.isfinite(x) for x in out.values()), out
    assert out["T_cmd"] == pytest.approx(out["T_max"], rel=1e-12) and np.sign(out["T_max"]) in (np.sign(T_ref), 0)
    assert abs(out["T_max"]) < 400  # the default motor's peak is 285 N.m
    assert math.hypot(out["i_d_ref"], out["i_q_ref"]) <= 500 * (1 + 1e-6)


@pytest.mark.parametrize("name", FMUS)
def test_hostile_step_sizes(make, name):
    a, ref = twins(make, name)
    run(a, 3, NORMAL[name]), run(ref, 3, NORMAL[name])
    for h in (0.0, -1e-4, -1.0, math.nan, math.inf, -math.inf):
        assert a.step(h=h) == ERROR, h
        assert "communicationStepSize" in a.log.text()
    assert a.step(h=1e-4, t=a.t + 1.0) == ERROR  # not where the last step ended
    assert a.step(h=1e-4, t=math.nan) == ERROR
    assert same(run(a, 3, NORMAL[name], 3), run(ref, 3, NORMAL[name], 3))
    # a 1 s step: done (finite outputs) or refused cleanly; then 100 us steps again
    before = a.outputs()
    status = a.step(h=1.0)
    assert status in (OK, WARNING, ERROR)
    if status == ERROR:
        assert a.outputs() == before and "was undone" in a.log.text()
    else:
        assert all(math.isfinite(x) for x in a.outputs())
    for h in (1e-9, 1e-4, 3.3e-4, 1e-3):  # variable communication steps (canHandleVariableCommunicationStepSize)
        a.set(**NORMAL[name])
        assert a.step(h=h) in (OK, WARNING) and all(math.isfinite(x) for x in a.outputs())


# --- flux maps ---

def _grid_csv(n=6, fold=False, duplicate=False, hole=False):
    rows = []
    for j in range(n):
        for k in range(n):
            i_d, i_q = -300 + 100.0 * j, -300 + 100.0 * k
            psi_d, psi_q = 0.08 + 0.25e-3 * i_d, 0.6e-3 * i_q
            if fold and j == 3 and k == 2:
                psi_d = 0.0  # psi_d falls with i_d there: no inverse, no positive inductance
            rows.append(f"{i_d},{i_q},{psi_d},{psi_q}")
    if duplicate:
        rows.append(rows[7])
    if hole:
        rows.pop(10)
    return "# a test map\ni_d,i_q,psi_d,psi_q\n" + "\n".join(rows) + "\n"


BAD_MAPS = {
    "missing": (None, "cannot open"),
    "a directory": ("<dir>", "directory"),
    "empty": ("", "empty file"),
    "only comments": ("# nothing here\n# pole_pairs: 4\n", "no header"),
    "header only": ("i_d,i_q,psi_d,psi_q\n", "header but no data"),
    "wrong header": ("id,iq,psid,psiq\n0,0,0.1,0\n", "wrong header"),
    "non-rectangular": (_grid_csv(hole=True), "not full and rectangular"),
    "duplicate points": (_grid_csv(duplicate=True), "duplicate grid point"),
    "non-monotonic flux": (_grid_csv(fold=True), "not strictly increasing"),
    "text in numbers": (_grid_csv().replace("0.08,", "0.o8,", 1), "is not a number"),
    "NaN in numbers": (_grid_csv().replace("0.08,", "nan,", 1), "non-finite"),
    "three columns": (_grid_csv().replace(",0.0\n", "\n", 1), "expected 4 comma-separated values"),
    "too small": ("i_d,i_q,psi_d,psi_q\n0,0,0.1,0\n0,1,0.1,0.1\n1,0,0.2,0\n1,1,0.2,0.1\n", "at least 4 x 4"),
    "binary garbage": ("\x00\xff\xfe\x01garbage,,,\n", None),
}


@pytest.mark.parametrize("name", FMUS)
@pytest.mark.parametrize("case", list(BAD_MAPS))
def test_bad_flux_maps_fail_cleanly(make, tmp_path, name, case):
    content, expected = BAD_MAPS[case]
    if content is None:
        path = tmp_path / "missing.csv"
    elif content == "<dir>":
        path = tmp_path
    else:
        path = tmp_path / "bad map.csv"
        path.write_bytes(content.encode("latin-1"))
    good = tmp_path / "good.csv"
    write_flux_map(good, linear_flux_map(0.25e-3, 0.6e-3, 0.08, 500.0, 9))
    a = make(name)
    assert a.setup() == OK and a.enter() == OK
    a.set(flux_map=str(path))
    assert a.get_status(a.names("output")[0])[0] == ERROR  # no initial outputs from a bad map either
    assert a.exit() == ERROR
    text = a.log.text()
    assert "flux map" in text and (expected is None or expected in text), text
    assert a.step() == ERROR  # still in Initialization Mode
    a.set(flux_map=str(good))
    assert a.exit() == OK
    assert all(math.isfinite(x) for row in run(a, 3, NORMAL[name]) for x in row)


# --- FMU states ---

@pytest.mark.parametrize("name", FMUS)
def test_fmu_state_round_trips_are_bit_identical(make, name):
    a = make(name)
    a.init()
    run(a, 10, varying(name))
    s, t_saved = a.get_state(), a.t
    blob = a.serialize(s)
    first = run(a, 20, varying(name), 10)
    assert a.set_state(s) == OK
    a.t = t_saved
    assert same(run(a, 20, varying(name), 10), first)
    status, d = a.deserialize_status(blob)
    assert status == OK and a.set_state(d) == OK
    a.t = t_saved
    assert same(run(a, 20, varying(name), 10), first)
    # into a fresh instance that was never initialised (the FMU loads its data itself)
    b = make(name)
    status, d2 = b.deserialize_status(blob)
    assert status == OK, b.log.text()
    assert b.set_state(d2) == OK
    b.t = t_saved
    assert same(run(b, 20, varying(name), 10), first)
    # a state reused (fmi2GetFMUstate into an existing one) and freed twice
    assert a.get_state(s) == s
    assert a.free_state(s) == OK and a.free_state(s) == ERROR


@pytest.mark.parametrize("name", FMUS)
def test_corrupted_serialized_states_are_refused(make, name):
    a, ref = twins(make, name)
    run(a, 5, NORMAL[name]), run(ref, 5, NORMAL[name])
    blob = a.serialize(a.get_state())
    rng = np.random.default_rng(5)
    cases = [blob[:n] for n in (0, 1, 8, 16, len(blob) // 2, len(blob) - 1)]
    cases += [blob + b"\x00", bytes(len(blob)), bytes(rng.integers(0, 256, len(blob), dtype=np.uint8))]
    for pos in rng.choice(len(blob), size=40, replace=False):
        flipped = bytearray(blob)
        flipped[pos] ^= 1 << int(rng.integers(0, 8))
        cases.append(bytes(flipped))
    for bad in cases:
        status, state = a.deserialize_status(bad)
        assert status == ERROR and state is None
    other = make("IpmsmPlant" if name == "IpmsmController" else "IpmsmController")
    other.init()
    status, _ = a.deserialize_status(other.serialize(other.get_state()))
    assert status == ERROR and "belongs to" in a.log.text()
    assert same(run(a, 5, NORMAL[name], 5), run(ref, 5, NORMAL[name], 5))


@pytest.mark.parametrize("name", FMUS)
def test_instances_in_two_threads_are_identical(make, name):
    """ctypes releases the GIL around the C calls: the instances really run at the same time."""
    sequential = make(name)
    sequential.init()
    expected = run(sequential, 300, varying(name))
    results, errors = {}, []

    def work(key):
        try:
            inst = make(name)
            inst.init()
            results[key] = run(inst, 300, varying(name))
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    assert all(same(results[i], expected) for i in range(3))


# --- the random-call-sequence fuzz (tests/cpp/fmu_fuzz.cpp) ---

UNDER_SANITIZER = os.environ.get("IPMSM_UNDER_SANITIZER") == "1"  # test_sanitizers.py: the ASan build
FUZZ_SEQUENCES = ({"IpmsmController": 1000, "IpmsmPlant": 300} if UNDER_SANITIZER
                  else {"IpmsmController": 2000, "IpmsmPlant": 1000})


def _fuzz(unzipped, name, args, wrapper=(), timeout=600):
    assert FUZZ_BIN.is_file(), f"{FUZZ_BIN} is missing: build the fmu_fuzz target"
    cmd = [*wrapper, str(FUZZ_BIN), str(unzipped(name).dir), *args]
    if name == "IpmsmController":
        cmd += FUZZ_SKIP
    env = None
    if UNDER_SANITIZER:  # the harness is built with ASan itself: no preload, and leak checking on
        env = {**os.environ, "LD_PRELOAD": "",
               "ASAN_OPTIONS": os.environ.get("ASAN_OPTIONS", "").replace("detect_leaks=0", "detect_leaks=1")}
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
    summary = [line for line in r.stdout.splitlines() if line.startswith(("fuzz ", "threads:"))]
    print("\n" + "\n".join(summary))
    return r, r.stdout[-6000:] + "\n" + r.stderr[-6000:]


@pytest.mark.parametrize("name", FMUS)
def test_random_call_sequences(unzipped, name):
    r, report = _fuzz(unzipped, name, ["--sequences", str(FUZZ_SEQUENCES[name]), "--seed", "1", "--threads"])
    assert r.returncode == 0, report
    assert "0 violations" in r.stdout and "bit-identical to the sequential run" in r.stdout, report


def test_plant_state_at_rest_with_thermal_network_serialises(unzipped):
    """A thermal network at rest (no loss, nodes at the boundaries' temperature) has every energy a
    few ulps: its heat balance is judged against the heat its nodes hold, so the plant's own state
    serialises (seed 760 saved such a state, then serialised it after fmi2Reset)."""
    r, report = _fuzz(unzipped, "IpmsmPlant", ["--sequences", "1", "--seed", "760"])
    assert r.returncode == 0 and "0 violations" in r.stdout, report


VALGRIND_SUPPRESSIONS = Path(__file__).resolve().parents[1] / "valgrind" / "known_model_bugs.supp"
VALGRIND_SEQUENCES = {"IpmsmController": 60, "IpmsmPlant": 30}


def _valgrind(suppressions=True):
    valgrind = shutil.which("valgrind")
    assert valgrind, "valgrind is not installed (scripts/setup.sh installs it)"
    return (valgrind, "--error-exitcode=99", "--leak-check=full", "--errors-for-leak-kinds=definite,indirect,possible",
            "--show-leak-kinds=definite,indirect,possible",
            *([f"--suppressions={VALGRIND_SUPPRESSIONS}"] if suppressions else []))


@pytest.mark.parametrize("name", FMUS)
def test_random_call_sequences_under_valgrind(unzipped, name):
    """memcheck: no invalid access, no use of uninitialised memory, no leak (known model bugs
    suppressed: tests/valgrind/known_model_bugs.supp, each with its xfail test)."""
    r, report = _fuzz(unzipped, name, ["--sequences", str(VALGRIND_SEQUENCES[name]), "--seed", "1000", "--threads"],
                      wrapper=_valgrind())
    assert r.returncode == 0, report
    assert "ERROR SUMMARY: 0 errors" in r.stderr, report


def test_serialised_controller_state_has_no_uninitialised_bytes_valgrind(unzipped):
    """Serialised FMU states carry no uninitialised bytes (models write fields, never padded structs)."""
    r, report = _fuzz(unzipped, "IpmsmController", ["--sequences", "60", "--seed", "1000"],
                      wrapper=_valgrind(suppressions=False))
    assert r.returncode == 0 and "ERROR SUMMARY: 0 errors" in r.stderr, report


@pytest.mark.slow
@pytest.mark.parametrize("name", FMUS)
def test_random_call_sequences_long(unzipped, name):
    r, report = _fuzz(unzipped, name, ["--sequences", "20000", "--seed", "100000"], timeout=3600)
    assert r.returncode == 0, report


@pytest.mark.slow
@pytest.mark.parametrize("name", FMUS)
def test_random_call_sequences_under_valgrind_long(unzipped, name):
    sequences = {"IpmsmController": 2000, "IpmsmPlant": 500}[name]
    r, report = _fuzz(unzipped, name, ["--sequences", str(sequences), "--seed", "5000", "--threads"],
                      wrapper=_valgrind(), timeout=7200)
    assert r.returncode == 0, report
    assert "ERROR SUMMARY: 0 errors" in r.stderr, report
