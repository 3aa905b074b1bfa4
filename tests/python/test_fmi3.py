"""The FMI 3.0 FMUs (build/fmu3/<Name>.fmu) are the FMI 2.0 ones under the other standard: the same
variables (value references, types, units, ranges, starts, causality, variability), the same
outputs bit for bit for the same inputs (golden_traces.py's 2000-step sequences in every
configuration, fmpy.simulate_fmu, a whole UDDS through the drive), valid by fmpy's checker, the
FMI 3.0 state API round trip and its refusal of a tampered state, and every refusal an fmi3Error
with a log line that is valid UTF-8 and bounded, the instance usable after it."""
from __future__ import annotations

import ctypes as C
import json
import re
import subprocess
import zipfile
from pathlib import Path

import fmi3_raw as f3
import fmpy
import golden_traces
import numpy as np
import pytest
import test_conformance as conformance
from fmpy.validation import validate_fmu

import fmi2_raw as raw
from conftest import BUILD_FMU3, WIN64_BUILT, fmu3_path, fmu_path

NAMES = ("IpmsmController", "IpmsmPlant", "IpmsmDrive")
#: bytes of a log message at most (fmu_src/fmi/log_text.hpp: 4000 characters)
MAX_LOG_CHARS = 4000
#: the value reference of FMI 3.0's independent variable time (fmu_src/fmi/standard.hpp: 2^31 - 1, fixed)
TIME_VR = 2**31 - 1
RELEASES = sorted((Path(__file__).resolve().parents[1] / "data").glob("value_references_*.json"))
#: every function fmi3Functions.h declares (the official header, fmu_src/fmi/headers3/)
FMI3_FUNCTIONS = {line.split()[-1].rstrip(";") for line in (
    Path(__file__).resolve().parents[2] / "fmu_src" / "fmi" / "headers3" / "fmi3Functions.h").read_text().splitlines()
    if line.startswith("FMI3_Export fmi3")}
#: the FMI 3.0 FMUs' variables FMI 2.0 cannot express: the flux map as arrays
MAP_ARRAYS = ("n_i_d", "n_i_q", "i_d_axis", "i_q_axis", "psi_d_map", "psi_q_map")
#: FMI 3.0's type of each FMI 2.0 type
FMI3_TYPE = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}


def assert_clean_log(text: str) -> None:
    """Every message bounded (the log decoded as UTF-8 already: Log._log)."""
    for line in text.splitlines():
        assert len(line) <= MAX_LOG_CHARS + 100, f"a log line of {len(line)} characters"


# --- the model description ---
@pytest.mark.parametrize("name", NAMES)
def test_fmpy_validate_finds_no_problem(name):
    assert validate_fmu(str(fmu3_path(name))) == []


@pytest.mark.parametrize("name", NAMES)
def test_the_same_variables_as_fmi2(name):
    md2 = fmpy.read_model_description(str(fmu_path(name)))
    md3 = fmpy.read_model_description(str(fmu3_path(name)))
    assert (md2.fmiVersion, md3.fmiVersion) == ("2.0", "3.0")
    assert md3.instantiationToken == md2.guid
    assert md3.coSimulation.modelIdentifier == md2.coSimulation.modelIdentifier == name
    assert md3.modelExchange is None and md3.scheduledExecution is None
    v3 = {v.name: v for v in md3.modelVariables}
    for v in md2.modelVariables:
        w = v3.pop(v.name)
        assert (w.valueReference, w.type, w.causality, w.variability, w.initial) == (
            v.valueReference, FMI3_TYPE[v.type], v.causality, v.variability, v.initial), v.name
        assert (w.unit, w.displayUnit, w.min, w.max, w.start) == (v.unit, v.displayUnit, v.min, v.max, v.start), v.name
    # FMI 3.0's own: the flux map as arrays (test_fmi3_arrays.py), after every FMI 2.0 variable
    arrays = {n: v3.pop(n) for n in MAP_ARRAYS}
    assert min(v.valueReference for v in arrays.values()) > max(v.valueReference for v in md2.modelVariables)
    # and the independent variable, at a fixed value reference beyond the table's
    (time,) = v3.values()
    assert (time.name, time.causality, time.type) == ("time", "independent", "Float64")
    assert time.valueReference == TIME_VR
    vr3 = {v.name: v.valueReference for v in md3.modelVariables}
    for release in RELEASES:  # as test_value_references.py checks the FMI 2.0 FMUs
        doc = json.loads(release.read_text())
        released, excused = doc["value_references"][name], doc.get("moved_since", {}).get(name, {})
        assert {n: vr3.get(n) for n in released if n not in excused} == {
            n: vr for n, vr in released.items() if n not in excused}
    # the structure: the same outputs, the same initial dependencies (FMI 2.0 by index, FMI 3.0 by vr)
    assert [u.variable.name for u in md3.outputs] == [u.variable.name for u in md2.outputs]
    assert all(not u.dependencies for u in md3.outputs)
    deps = {u.variable.name: sorted(d.name for d in u.dependencies) for u in md2.initialUnknowns}
    assert {u.variable.name: sorted(d.name for d in u.dependencies if d.name not in MAP_ARRAYS)
            for u in md3.initialUnknowns} == deps


@pytest.mark.parametrize("name", NAMES)
def test_the_binaries_export_the_fmi3_functions_only(name):
    with zipfile.ZipFile(fmu3_path(name)) as z:
        files = set(z.namelist())
    assert f"binaries/x86_64-linux/{name}.so" in files
    assert not any(f.startswith(("binaries/linux64", "binaries/win64")) for f in files)
    if WIN64_BUILT:
        assert f"binaries/x86_64-windows/{name}.dll" in files
    declared = FMI3_FUNCTIONS
    assert len(declared) == 75
    with zipfile.ZipFile(fmu3_path(name)) as z:
        data = z.read(f"binaries/x86_64-linux/{name}.so")
    so = BUILD_FMU3 / name / "binaries" / "x86_64-linux" / f"{name}.so"
    assert so.read_bytes() == data
    out = subprocess.run(["nm", "-D", "--defined-only", str(so)], capture_output=True, text=True, check=True).stdout
    exported = {line.split()[-1] for line in out.splitlines() if line.split()[-2] in ("T", "W")}
    assert exported == declared


def _needed(lib: Path) -> set[str]:
    dyn = subprocess.run(["readelf", "-d", str(lib)], check=True, capture_output=True, text=True).stdout
    return set(re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", dyn))


@pytest.mark.parametrize("name", NAMES)
def test_the_binaries_are_linked_as_the_fmi2_ones(name, unzipped, unzipped3):
    """The same recipe (add_fmu): the same C runtime needs and symbol versions (test_conformance.py
    checks the FMI 2.0 ones against the glibc baseline), win64 only system DLLs and fmi3* exports."""
    so2 = unzipped(name).library
    so3 = Path(unzipped3(name).directory) / "binaries" / "x86_64-linux" / f"{name}.so"
    assert _needed(so3) == _needed(so2)
    assert conformance._versions(so3) == conformance._versions(so2)
    if not WIN64_BUILT:
        return
    pe = conformance._pe_headers(Path(unzipped3(name).directory) / "binaries" / "x86_64-windows" / f"{name}.dll")
    imported = set(re.findall(r"DLL Name: (\S+)", pe))
    assert imported and all(conformance.WINDOWS_SYSTEM_DLLS.fullmatch(d) for d in imported), imported
    table = pe.split("[Ordinal/Name Pointer] Table", 1)[1].split("\n\n", 1)[0]
    exported = set(re.findall(r"^\s*\[\s*\d+\] (\S+)$", table, re.MULTILINE))
    assert exported == FMI3_FUNCTIONS


# --- the same outputs, bit for bit ---
@pytest.fixture(scope="module")
def fmi2_unzipped(tmp_path_factory):
    return {n: raw.Unzipped(fmu_path(n), tmp_path_factory.mktemp(f"{n}2")) for n in NAMES}


@pytest.mark.parametrize("config", sorted(golden_traces.CONFIGS))
def test_golden_traces_bit_for_bit_with_fmi2(config, fmi2_unzipped, unzipped3):
    fmi2 = golden_traces.run(config, fmi2_unzipped)
    fmi3 = golden_traces.run(config, {n: unzipped3(n) for n in NAMES}, f3.Instance3)
    assert sorted(fmi3) == sorted(fmi2)
    changed = [k for k in fmi2 if fmi2[k].tobytes() != fmi3[k].tobytes()]
    assert not changed, f"{config}: FMI 3.0 differs from FMI 2.0 in {changed}"
    assert all(len(c) == golden_traces.N_STEPS + 1 for c in fmi3.values())


@pytest.mark.parametrize("name", NAMES)
def test_fmpy_simulates_both_alike(name):
    md = fmpy.read_model_description(str(fmu_path(name)))
    stop = 200 * float(md.defaultExperiment.stepSize)
    r2 = fmpy.simulate_fmu(str(fmu_path(name)), stop_time=stop)
    r3 = fmpy.simulate_fmu(str(fmu3_path(name)), stop_time=stop)
    assert r3.dtype.names == r2.dtype.names and len(r3) == len(r2) == 201
    assert r2.tobytes() == r3.tobytes()


class _RecordedDrive:
    """What a run did with its IpmsmDrive (scenarios.runs.simulate's DriveFmu): its parameters and
    start inputs, then each step's (dt, inputs) and the outputs it gave."""

    def __init__(self):
        self.params, self.start, self.steps = None, None, []


@pytest.fixture(scope="module")
def udds_on_fmi2():
    """A whole UDDS run (the default RunSpec: the IpmsmDrive backend) on the FMI 2.0 drive, recorded."""
    from scenarios.cosim import drive_fmu
    from scenarios.runs import simulate as sim

    record = _RecordedDrive()

    class Recording(drive_fmu.DriveFmu):
        def __init__(self, path, params=None, **start):
            record.params, record.start = dict(params or {}), dict(start)
            super().__init__(path, params, **start)

        def advance(self, dt, *inputs):
            r = super().advance(dt, *inputs)
            record.steps.append((dt, inputs, r))
            return r

        def set_fault(self, on):
            raise AssertionError("the default run has no fault")

    original = sim.DriveFmu
    sim.DriveFmu = Recording
    try:
        summary = sim.simulate("UDDS", progress=False)
    finally:
        sim.DriveFmu = original
    return summary, record


@pytest.mark.slow
def test_a_whole_udds_through_the_fmi3_drive_bit_for_bit(udds_on_fmi2, unzipped3):
    """The FMI 3.0 IpmsmDrive, fed what the FMI 2.0 one was fed over a whole UDDS (the vehicle side's
    inputs, step by step), gives every output the run recorded bit for bit."""
    summary, record = udds_on_fmi2
    assert len(record.steps) > 100_000  # 1369 s at 10 ms
    fmu = unzipped3("IpmsmDrive")
    inst = f3.Instance3(fmu, "udds")
    try:
        start = record.start
        boundary = {k: start.pop(k) for k in ("T_coolant", "T_ambient") if k in start}
        assert inst.enter() == f3.OK
        inst.set(**record.params)
        inputs = ("T_ref", "w_m", "u_dc", "T_magnet", "T_winding", *boundary)
        inst.set(**dict(zip(inputs, (start.get("T_ref", 0.0), start["w_m"], start["u_dc"], start["T_magnet"],
                                     start["T_winding"], *boundary.values()))))
        assert inst.exit() == f3.OK, inst.log.text()
        first = record.steps[0][2]
        reals = [f for f in type(first).__dataclass_fields__ if isinstance(getattr(first, f), float)
                 and f in fmu.vars and fmu.vars[f].type == "Float64"]
        ints = [f for f in type(first).__dataclass_fields__ if f in fmu.vars and fmu.vars[f].type == "Int32"]
        u_vr = [fmu.vars[n].valueReference for n in inputs]
        y_vr = [fmu.vars[n].valueReference for n in reals]
        n_vr = [fmu.vars[n].valueReference for n in ints]
        u_refs, y_refs, n_refs = f3.vrs(u_vr), f3.vrs(y_vr), f3.vrs(n_vr)
        y_out, n_out = (C.c_double * len(y_vr))(), (C.c_int32 * len(n_vr))()
        differ = []
        for k, (dt, u, r) in enumerate(record.steps):
            values = f3.array(C.c_double, [*u, *boundary.values()])
            assert inst.call("fmi3SetFloat64", inst.c, u_refs, len(u_vr), values, len(u_vr)) == f3.OK
            assert inst.step(dt) == f3.OK, inst.log.text()
            assert inst.call("fmi3GetFloat64", inst.c, y_refs, len(y_vr), y_out, len(y_vr)) == f3.OK
            assert inst.call("fmi3GetInt32", inst.c, n_refs, len(n_vr), n_out, len(n_vr)) == f3.OK
            y, n = list(y_out), list(n_out)
            want = [getattr(r, f) for f in reals]
            if np.array(y).tobytes() != np.array(want).tobytes() or n != [getattr(r, f) for f in ints]:
                differ.append(k)
        assert not differ, f"{len(differ)} of {len(record.steps)} steps differ, the first at {differ[0]}"
        assert summary is not None
    finally:
        inst.free()


# --- the FMI 3.0 state API ---
H = {"IpmsmController": 1e-4, "IpmsmPlant": 1e-4, "IpmsmDrive": 1e-3}


def _started(new, name: str) -> f3.Instance3:
    inst = new(name)
    inst.init()
    return inst


def _trace(inst: f3.Instance3, name: str, k0: int, n: int) -> list[tuple]:
    """n steps from step k0 with golden_traces' inputs (those the FMU has); the outputs after each."""
    ins = set(inst.names("input"))
    rows = []
    for k in range(k0, k0 + n):
        inst.set(**{n_: v for n_, v in golden_traces.inputs(k).items() if n_ in ins})
        assert inst.step(H[name]) == f3.OK, inst.log.text()
        rows.append(inst.outputs())
    return rows


@pytest.mark.parametrize("name", NAMES)
def test_state_round_trip_continues_bit_for_bit(name, instances3):
    inst = _started(instances3, name)
    _trace(inst, name, 0, 30)
    state = inst.get_state()
    data = inst.serialize(state)
    t = inst.t
    first = _trace(inst, name, 30, 30)
    # back through the serialised bytes, into this instance and into a fresh, uninitialised one
    inst.restore(data, t)
    assert inst.get("time") == t  # the independent variable: where the instance is
    again = _trace(inst, name, 30, 30)
    other = instances3(name, "other")
    other.restore(data, t)
    elsewhere = _trace(other, name, 30, 30)
    assert repr(first) == repr(again) == repr(elsewhere)
    # and without serialising: fmi3SetFMUState of the state kept
    assert inst.set_state(state) == f3.OK
    inst.t = t
    assert repr(_trace(inst, name, 30, 30)) == repr(first)
    assert inst.free_state(state) == f3.OK
    assert inst.serialize(inst.get_state()) != data  # a state is the instance's now, not a copy of the first


@pytest.mark.parametrize("name", NAMES)
def test_a_tampered_state_is_refused_and_changes_nothing(name, instances3):
    inst = _started(instances3, name)
    _trace(inst, name, 0, 10)
    data = inst.serialize(inst.get_state())
    t = inst.t
    before = inst.outputs()
    for bad, why in ((data[:len(data) // 2] + bytes([data[len(data) // 2] ^ 0x10]) + data[len(data) // 2 + 1:],
                      "checksum mismatch"),
                     (data[:-9], "checksum mismatch"),
                     (b"IPMSMFST" + data[8:20], "corrupt or truncated"),
                     (b"NOTASTAT" + data[8:], "is not one")):
        inst.log.clear()
        status, state = inst.deserialize_status(bad)
        assert status == f3.ERROR and not state
        assert "fmi3DeserializeFMUState" in inst.log.text() and why in inst.log.text(), inst.log.text()
        assert_clean_log(inst.log.text())
    assert inst.outputs() == before and inst.t == t
    assert len(_trace(inst, name, 10, 3)) == 3  # still usable


# --- refusals: fmi3Error, a log line, the instance usable ---
def test_a_parameter_out_of_range_is_refused_with_a_bounded_utf8_line(instances3):
    inst = instances3("IpmsmController")
    assert inst.enter() == f3.OK
    kept = inst.get("R_s")
    text = raw.refused(inst, inst.set_status, "R_s", -1.0, match="R_s")
    assert "fmi3SetFloat64" in text and "kept" in text
    assert inst.get("R_s") == kept
    assert len(inst.log.records) == 1 and len(inst.log.messages()[0]) <= MAX_LOG_CHARS
    # a String parameter with bytes that are not UTF-8 and a huge length: the refusal's line is
    # valid UTF-8 and bounded
    huge = b"\xff\xfe" + b"/no/such/map" * 20_000 + b".csv"
    vr = (C.c_uint32 * 1)(inst.fmu.vars["flux_map"].valueReference)
    assert inst.call("fmi3SetString", inst.c, vr, 1, (C.c_char_p * 1)(huge), 1) == f3.OK
    inst.log.clear()
    assert inst.exit() == f3.ERROR
    assert all(len(m) <= MAX_LOG_CHARS for m in inst.log.messages()) and "flux map" in inst.log.text()
    assert "\\xFF\\xFE/no/such/map" in inst.log.text()  # the bytes that are not UTF-8, escaped
    inst.set(flux_map="")
    assert inst.exit() == f3.OK, inst.log.text()  # usable: corrected and called again
    assert inst.step(1e-4) == f3.OK


def test_wrong_state_null_pointers_and_unsupported_functions_are_refused(instances3):
    inst = instances3("IpmsmPlant")
    refused = raw.refused
    # a step before initialisation, then the wrong communication point
    refused(inst, inst.step, 1e-4, match="fmi3DoStep is not allowed in state Instantiated (allowed in: StepMode)")
    inst.init()
    refused(inst, inst.step, 1e-4, 0.5, match="previous step ended at 0")
    assert inst.step(1e-4) == f3.OK
    vr_time = C.c_uint32(inst.fmu.vars["time"].valueReference)
    assert inst.get("time") == inst.t
    refused(inst, inst.set_status, "time", 1.0, match="independent variable")
    b = C.c_bool()
    d = C.c_double()
    vr = (C.c_uint32 * 2)(0, 1)
    out = (C.c_double * 2)()
    for call, args, match in (
            ("fmi3DoStep", (inst.c, inst.t, 1e-4, True, None, C.byref(b), C.byref(b), C.byref(d)), "NULL"),
            ("fmi3GetFloat64", (inst.c, vr, 2, out, 1), "nValues = 1 but nValueReferences = 2"),
            ("fmi3GetFloat64", (inst.c, None, 2, out, 2), "NULL"),
            ("fmi3GetFloat64", (inst.c, C.byref(vr_time), 1, out, 1), None),  # (OK: the time)
            ("fmi3GetFloat32", (inst.c, vr, 1, (C.c_float * 1)(), 1), "has no Float32 variable"),
            ("fmi3SetUInt64", (inst.c, vr, 1, (C.c_uint64 * 1)(), 1), "not a UInt64"),
            ("fmi3SetInt64", (inst.c, vr, 1, (C.c_int64 * 1)(), 1), "has no Int64 variable"),
            ("fmi3GetClock", (inst.c, vr, 1, (C.c_bool * 1)()), "has no Clock variable"),
            ("fmi3EnterEventMode", (inst.c,), "no Event Mode"),
            ("fmi3EnterStepMode", (inst.c,), "Step Mode"),
            ("fmi3EnterConfigurationMode", (inst.c,), "not allowed in state StepMode"),
            ("fmi3UpdateDiscreteStates", (inst.c, None, None, None, None, None, None), "no Event Mode"),
            ("fmi3GetIntervalDecimal", (inst.c, vr, 1, out, None), "no clocks"),
            ("fmi3GetDirectionalDerivative", (inst.c, vr, 1, vr, 1, out, 1, out, 1), "providesDirectional"),
            ("fmi3GetOutputDerivatives", (inst.c, vr, 1, None, out, 1), "maxOutputDerivativeOrder"),
            ("fmi3GetNumberOfContinuousStates", (inst.c, None), "co-simulation only"),
            ("fmi3SetTime", (inst.c, 0.0), "co-simulation only"),
            ("fmi3GetVariableDependencies", (inst.c, 0, None, None, None, None, 0), "ModelStructure")):
        inst.log.clear()
        status = inst.call(call, *args)
        if match is None:
            assert status == f3.OK and out[0] == inst.t
            continue
        assert status == f3.ERROR, f"{call}: {status}"
        assert len(inst.log.records) == 1 and call in inst.log.text() and match in inst.log.text(), inst.log.text()
        assert_clean_log(inst.log.text())
    # a NULL or foreign instance: fmi3Error, nobody to log to
    assert inst.call("fmi3Terminate", None) == f3.ERROR
    assert inst.call("fmi3DoStep", C.c_void_p(C.addressof(d)), 0.0, 1e-4, True, None, None, None, None) == f3.ERROR
    assert inst.step(1e-4) == f3.OK  # the instance is as it was
    assert inst.terminate() == f3.OK and inst.reset() == f3.OK
    inst.init()
    assert inst.step(1e-4) == f3.OK


def test_instantiation_refusals_log_why(unzipped3):
    fmu = unzipped3("IpmsmController")
    probe = f3.Instance3(fmu, "probe")
    log = f3.Log()
    no_update = f3.IntermediateUpdate()
    resources = (Path(fmu.directory) / "resources").as_posix().encode() + b"/"
    try:
        def args(name: bytes, token: str, event_mode_used: bool):
            return (name, token.encode(), resources, False, False, event_mode_used, False, None, 0, None,
                    log.callback, no_update)

        for arguments, match in ((args(b"x", "{wrong}", False), "does not match"),
                                 (args(b"x", fmu.guid, True), "eventModeUsed must be false"),
                                 (args(b"", fmu.guid, False), "instanceName")):
            log.clear()
            assert not probe.call("fmi3InstantiateCoSimulation", *arguments)
            assert match in log.text() and "fmi3InstantiateCoSimulation" in log.text(), log.text()
        log.clear()
        assert not probe.call("fmi3InstantiateModelExchange", b"x", fmu.guid.encode(), resources, False, False, None,
                              log.callback)
        assert "co-simulation FMU only" in log.text()
        # without a resource path the model warns and has no resources directory
        log.clear()
        c = probe.call("fmi3InstantiateCoSimulation", b"x", fmu.guid.encode(), None, False, True, False, False, None, 0,
                       None, log.callback, no_update)
        assert c and "resourcePath is NULL" in log.text()
        probe.call("fmi3FreeInstance", c)
    finally:
        probe.free()


@pytest.mark.parametrize("name", NAMES)
def test_a_state_serialised_by_the_fmi2_fmu_continues_in_the_fmi3_fmu(name, fmu_instances, instances3):
    """One serialised format for both standards (fmu_src/fmi/README.md): a state saved by the FMI
    2.0 FMU continues in the FMI 3.0 one as it does in the FMI 2.0 one, bit for bit."""
    two = fmu_instances(name, "two")
    two.init()
    _trace(two, name, 0, 20)
    data, t = two.serialize(two.get_state()), two.t
    in_two = _trace(two, name, 20, 20)
    three = instances3(name, "three")
    three.restore(data, t)
    assert repr(_trace(three, name, 20, 20)) == repr(in_two)


def test_an_fmi2_instance_is_foreign_to_the_fmi3_library(fmu_instances, instances3):
    """The same model under the other standard: its instance pointer is refused, nothing touched."""
    two = fmu_instances("IpmsmPlant", "two")
    two.init()
    three = instances3("IpmsmPlant", "three")
    b, d = C.c_bool(), C.c_double()
    assert three.call("fmi3DoStep", two.c, 0.0, 1e-4, True, C.byref(b), C.byref(b), C.byref(b), C.byref(d)) == f3.ERROR
    assert three.call("fmi3Terminate", two.c) == f3.ERROR
    assert two.fmu.fmi2DoStep(three.c, 0.0, 1e-4, 1) == raw.ERROR
    assert two.step(1e-4) == raw.OK and two.t == 1e-4
