"""The hostile corpus against the FMI 3.0 entry points (issue 36), through the raw C API
(fmi3_raw.py), for each FMI 3.0 FMU (build/fmu3): NULL for every pointer argument of every
function (and a NULL instance), calls in the wrong state, tampered serialized FMU states, huge
counts with bad value references and huge structural parameters, and bad UTF-8 instance names.

"Refused cleanly" means, as for the FMI 2.0 entry points (test_hostile.py): the call returns
fmi3Error; the FMU logs why, every message valid UTF-8 and bounded (LOG_BOUND) whatever the input's
size; and the instance stays usable: it then steps exactly as an untouched twin. Each case runs in
a forked child (`isolated`), so that a crash or a hang is reported as the case's failure, naming
the signal, instead of ending the test run.
"""
from __future__ import annotations

import ctypes as C
import os
import signal
import time
import traceback

import fmi3_raw as raw
import numpy as np
import pytest
from fmi3_raw import ERROR, OK, WARNING

from conftest import patient, same

FMUS = ["IpmsmController", "IpmsmPlant", "IpmsmDrive"]
#: bytes: the longest log message allowed. The glue cuts a message at fmi::kMaxLogChars = 4000
#: characters (fmu_src/fmi/log_text.hpp), of at most 4 bytes each in UTF-8, plus its context.
LOG_BOUND = 4 * 4000 + 1000
#: s: a case that has not finished by then hangs (the child is stopped by SIGALRM)
CASE_TIMEOUT = 120
#: s: a refusal of a huge count takes no longer than this (it must not walk the count)
HUGE_COUNT_SECONDS = 1.0
HUGE = (1 << 40, (1 << 63) - 1, (1 << 64) - 1)
#: communication steps before and after the hostile calls (the twin takes the same)
STEPS = 5


# --- the forked child ---

#: in the forked child: the pipe to the parent, where `doing` writes what the case is at
_TO_PARENT: list = []


def doing(what: str) -> None:
    """Tell the parent what the case is about to do (a crash is reported with the last one)."""
    if _TO_PARENT:
        os.write(_TO_PARENT[0], ("doing " + what.replace("\n", " ")[:500] + "\n").encode())


def isolated(case, *args):
    """case(*args) in a forked child; its failure (an assertion, an exception, a signal: a crash
    or a hang past CASE_TIMEOUT, reported with what the case was doing) is this test's failure."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        os.close(r)
        _TO_PARENT.append(w)
        signal.alarm(int(patient(CASE_TIMEOUT)))
        try:
            case(*args)
            result = "ok"
        except BaseException:  # noqa: BLE001 - every failure goes to the parent
            result = "failed " + traceback.format_exc(limit=6)[-6000:].replace("\n", "\\n")
        os.write(w, (result + "\n").encode())
        os._exit(0)
    os.close(w)
    with os.fdopen(r, "rb") as f:
        lines = f.read().decode(errors="replace").splitlines()
    _, status = os.waitpid(pid, 0)
    last = next((line[6:] for line in reversed(lines) if line.startswith("doing ")), "(before its first call)")
    if os.WIFSIGNALED(status):
        sig = signal.Signals(os.WTERMSIG(status)).name
        pytest.fail(f"the case {'hung' if sig == 'SIGALRM' else 'crashed'} ({sig}) at: {last}")
    if not lines or lines[-1] != "ok":
        pytest.fail(lines[-1][len("failed "):].replace("\\n", "\n") if lines else f"no result (status {status})",
                    pytrace=False)


# --- what every case checks ---

def step_size(u: raw.Unzipped3) -> float:
    d = u.md.defaultExperiment
    return float(d.stepSize) if d and d.stepSize else float(d.stopTime) / 50


def inputs(u: raw.Unzipped3):
    """The scalar Float64 inputs, as (variable, start)."""
    return [(v, float(v.start or 0.0)) for v in u.md.modelVariables
            if v.causality == "input" and v.type == "Float64" and not v.dimensions]


def run(inst: raw.Instance3, k0: int, n: int = STEPS) -> list:
    """n steps from step k0, each Float64 input a little off its start value; the outputs after each."""
    u, h, rows = inst.fmu, step_size(inst.fmu), []
    for k in range(k0, k0 + n):
        for i, (v, start) in enumerate(inputs(u)):
            x = start + 0.1 * np.sin(0.3 * k + i)
            if v.max is not None:
                x = min(x, float(v.max))
            assert inst.set_status(v.name, x) == OK, inst.log.text()
        status = inst.step(h, t=k * h)
        assert status in (OK, WARNING), f"step {k}: {raw.STATUS.get(status, status)}\n{inst.log.text()[-3000:]}"
        rows.append(inst.float64_outputs())
    return rows


def twins(u: raw.Unzipped3) -> tuple[raw.Instance3, raw.Instance3]:
    """Two initialised instances, each STEPS steps on."""
    a, b = raw.Instance3(u, b"hostile"), raw.Instance3(u, b"twin")
    for inst in (a, b):
        assert inst.c, "fmi3InstantiateCoSimulation returned NULL"
        inst.init()
        run(inst, 0)
    return a, b


def usable(a: raw.Instance3, twin: raw.Instance3, k0: int = STEPS) -> None:
    """a steps exactly as its untouched twin."""
    assert same(run(a, k0), run(twin, k0)), "the instance no longer steps as its untouched twin"


def logged_well(messages: list[bytes], what: str) -> None:
    for m in messages:
        try:
            m.decode("utf-8")
        except UnicodeDecodeError:
            raise AssertionError(f"{what}: a log message is not valid UTF-8: {m[:200]!r}") from None
        assert len(m) <= LOG_BOUND, f"{what}: a log message of {len(m)} bytes (> {LOG_BOUND}): {m[:200]!r}..."


def refused(inst: raw.Instance3, what: str, call, *args) -> None:
    """call(*args) returns fmi3Error and the FMU logs why, in valid, bounded UTF-8."""
    doing(what)
    n = len(inst.log.records)
    status = call(*args)
    assert status == ERROR, f"{what}: {raw.STATUS.get(status, status)}, not fmi3Error\n{inst.log.text()[-2000:]}"
    said = inst.log.since(n)
    assert said, f"{what}: refused without a log message"
    logged_well(said, what)


# --- arguments for every function ---

def _variable_of(u: raw.Unzipped3, kind: str, settable: bool):
    """A scalar variable of the FMI 3.0 type kind (settable: an input or a tunable parameter)."""
    for v in u.md.modelVariables:
        if v.type == kind and not v.dimensions and (
                not settable or v.causality == "input" or (v.causality == "parameter" and v.variability == "tunable")):
            return v
    return None


def arguments(u: raw.Unzipped3, name: str, inst, state) -> list:
    """Valid-looking arguments of `name` (counts of 1, arrays of one value of the right type, a
    value reference of that type where the FMU has one), so that only what a test changes is wrong."""
    _, argtypes = raw.SIGNATURES[name]
    kind = next((k for k in raw.VALUE_TYPES if name in (f"fmi3Get{k}", f"fmi3Set{k}")), None)
    v = _variable_of(u, kind, name.startswith("fmi3Set")) if kind else None
    ref = v.valueReference if v is not None else 0
    args = []
    for i, t in enumerate(argtypes):
        if i == 0:
            args.append(inst)
        elif t is C.c_void_p:  # fmi3FMUState (or the instance environment)
            args.append(state)
        elif t is C.c_size_t:
            args.append(1)
        elif t is C.c_bool:
            args.append(False)
        elif t in (C.c_double, C.c_float):
            args.append(0.0)
        elif t is C.c_uint32:
            args.append(ref)
        elif t is raw.vr_p:
            args.append(raw.vrs([ref]))
        elif t is raw.state_p:
            args.append(C.pointer(C.c_void_p()))
        elif t is C.POINTER(C.c_char_p):
            args.append((C.c_char_p * 1)(b"x"))
        elif t is C.POINTER(raw.byte_p):
            args.append((raw.byte_p * 1)((C.c_uint8 * 8)()))
        elif t is raw.byte_p:
            args.append((C.c_uint8 * 64)())
        elif is_pointer(t):  # a pointer to values: an array of 8 zeros of its type
            args.append((t._type_ * 8)())
        else:
            raise AssertionError(f"{name}: no argument for type {t}")
    return args


def is_pointer(t) -> bool:
    return t is C.c_void_p or issubclass(t, C._Pointer)


def pointer_positions(name: str) -> list[int]:
    """The arguments of `name` that are pointers (after the instance)."""
    _, argtypes = raw.SIGNATURES[name]
    return [i for i, t in enumerate(argtypes) if i > 0 and is_pointer(t)]


#: NULL arguments the standard allows: fmi3FreeFMUState "If a null pointer is provided, the call is
#: ignored" (FMI 3.0, 2.2.6.4): OK or fmi3Error, never a crash
NULL_ALLOWED = {("fmi3FreeFMUState", 1)}
INSTANCE_FUNCTIONS = sorted(n for n in raw.SIGNATURES
                            if n not in ("fmi3GetVersion", "fmi3FreeInstance") and not n.startswith("fmi3Instantiate"))


# --- the cases ---

def _null_instance(u):
    inst = raw.Instance3(u, b"owner")  # a real state to pass where one is asked
    inst.init()
    ok, s = inst.get_state_status()
    assert ok == OK, inst.log.text()
    for name in sorted(u.exported & set(INSTANCE_FUNCTIONS)):
        args = arguments(u, name, None, s)
        doing(f"{name}(NULL instance, ...)")
        status = getattr(u, name)(*args)
        assert status == ERROR, f"{name}(NULL instance, ...): {raw.STATUS.get(status, status)}"
    u.fmi3FreeInstance(None)
    logged_well(inst.log.since(0), "the owner")


def _null_pointers(u):
    a, twin = twins(u)
    ok, s = a.get_state_status()
    assert ok == OK, a.log.text()
    tried, h = 0, step_size(u)
    for name in sorted(u.exported & set(INSTANCE_FUNCTIONS)):
        for i in pointer_positions(name):
            args = arguments(u, name, a.c, s)
            if name == "fmi3DoStep":  # a step that would be taken but for the NULL
                args[1:3] = [STEPS * h, h]
            args[i] = None
            if (name, i) in NULL_ALLOWED:
                doing(f"{name} with argument {i} NULL")
                assert getattr(u, name)(*args) in (OK, ERROR)
                continue
            refused(a, f"{name} with argument {i} NULL", getattr(u, name), *args)
            tried += 1
    assert tried > 40, f"only {tried} NULL arguments tried"
    print(f"\n[{u.id}] NULL refused in {tried} pointer arguments of {len(u.exported & set(INSTANCE_FUNCTIONS))} "
          f"functions", flush=True)
    usable(a, twin)


def _wrong_state(u):
    h = step_size(u)
    a, twin = raw.Instance3(u, b"hostile"), raw.Instance3(u, b"twin")
    refused(a, "fmi3DoStep in Instantiated", a.step, h, 0.0)
    refused(a, "fmi3ExitInitializationMode in Instantiated", a.exit)
    refused(a, "fmi3EnterEventMode without event mode", u.fmi3EnterEventMode, a.c)
    assert a.enter() == OK, a.log.text()
    refused(a, "fmi3DoStep in Initialization Mode", a.step, h, 0.0)
    refused(a, "fmi3EnterInitializationMode twice", a.enter)
    assert a.exit() in (OK, WARNING), a.log.text()
    refused(a, "fmi3ExitInitializationMode in Step Mode", a.exit)
    refused(a, "fmi3EnterInitializationMode in Step Mode", a.enter)
    refused(a, "fmi3EnterEventMode, instantiated without event mode", u.fmi3EnterEventMode, a.c)
    refused(a, "fmi3DoStep with a negative step", a.step, -h, 0.0)
    refused(a, "fmi3DoStep from another time", a.step, h, 1e9)
    twin.init()
    assert same(run(a, 0), run(twin, 0)), "the instance no longer steps as its untouched twin"
    # after fmi3Terminate: no more inputs or steps; fmi3Reset starts again
    assert a.terminate() == OK, a.log.text()
    (v, start), *_ = inputs(u)
    refused(a, "fmi3SetFloat64 of an input after fmi3Terminate", a.set_status, v.name, start)
    refused(a, "fmi3DoStep after fmi3Terminate", a.step, h, STEPS * h)
    refused(a, "fmi3Terminate twice", a.terminate)
    assert a.reset() == OK, a.log.text()
    a.init()
    fresh = raw.Instance3(u, b"fresh")
    fresh.init()
    assert same(run(a, 0), run(fresh, 0)), "after fmi3Reset the instance does not step as a fresh one"


def _tampered_states(u, other: raw.Unzipped3):
    a, twin = twins(u)
    ok, s = a.get_state_status()
    assert ok == OK, a.log.text()
    blob = a.serialize(s)
    rng = np.random.default_rng(36)
    cases = {f"truncated to {n} bytes": blob[:n] for n in sorted({0, 1, 8, 16, len(blob) // 2, len(blob) - 1})}
    cases["one byte more"] = blob + b"\x00"
    cases["all zeros"] = bytes(len(blob))
    cases["random bytes"] = bytes(rng.integers(0, 256, len(blob), dtype=np.uint8))
    for pos in rng.choice(len(blob), size=min(40, len(blob)), replace=False):
        flipped = bytearray(blob)
        flipped[pos] ^= 1 << int(rng.integers(0, 8))
        cases[f"bit flipped at byte {pos}"] = bytes(flipped)
    for pos in range(0, max(1, len(blob) - 8), max(8, (len(blob) // 16) & ~7)):  # a huge size or count
        huge = bytearray(blob)
        huge[pos:pos + 8] = b"\xff" * 7 + b"\x7f"
        cases[f"a huge number at byte {pos}"] = bytes(huge)
    other_inst = raw.Instance3(other, b"other")
    other_inst.init()
    _, other_state = other_inst.get_state_status()
    if other.id != u.id:
        cases[f"a state of {other.id}"] = other_inst.serialize(other_state)
    print(f"\n[{u.id}] {len(cases)} tampered states of a {len(blob)}-byte state", flush=True)
    for what, bad in cases.items():
        refused(a, f"fmi3DeserializeFMUState of the state {what}", lambda blob: a.deserialize_status(blob)[0], bad)
    # the genuine state is taken, and is the instance as it was
    status, d = a.deserialize_status(blob)
    assert status == OK, a.log.text()
    assert u.fmi3SetFMUState(a.c, d) == OK, a.log.text()
    usable(a, twin)


def _huge_counts(u):
    a, twin = twins(u)
    (v, _), *_ = inputs(u)
    out = next(x for x in u.md.modelVariables if x.causality == "output" and x.type == "Float64")
    bad = max(x.valueReference for x in u.md.modelVariables) + 1000
    values = (C.c_double * 2)()
    for n in HUGE:
        for what, refs, n_refs, n_values in (
                ("a bad first value reference", raw.vrs([bad, v.valueReference]), n, n),
                ("a bad second value reference, one value", raw.vrs([v.valueReference, bad]), n, 1),
                ("one reference, a huge count of values", raw.vrs([v.valueReference]), 1, n)):
            for f in ("fmi3SetFloat64", "fmi3GetFloat64"):
                t0 = time.perf_counter()
                refused(a, f"{f} with {n_refs} references and {n_values} values, {what}",
                        getattr(u, f), a.c, refs, n_refs, values, n_values)
                assert time.perf_counter() - t0 < patient(HUGE_COUNT_SECONDS), f"{f} with {n}: walked the count?"
        refused(a, f"fmi3SetDebugLogging with {n} categories, the first unknown",
                u.fmi3SetDebugLogging, a.c, True, n, (C.c_char_p * 1)(b"no such category"))
    # all or nothing: a good reference before a bad one changes nothing
    refs = raw.vrs([v.valueReference, bad])
    refused(a, "fmi3SetFloat64 of a good and a bad reference",
            u.fmi3SetFloat64, a.c, refs, 2, raw.array(C.c_double, [123.0, 1.0]), 2)
    refused(a, "fmi3GetFloat64 of a scalar output with 2 values",
            u.fmi3GetFloat64, a.c, raw.vrs([out.valueReference]), 1, values, 2)
    usable(a, twin)
    # before initialisation (where they may be set): structural parameters (an array's length) at
    # their type's largest value, and array parameters given a huge count of values; refused in
    # bounded time, and the instance then initialises and steps as a fresh one
    b, fresh = raw.Instance3(u, b"structural"), raw.Instance3(u, b"fresh")
    for x in u.md.modelVariables:
        if x.causality == "structuralParameter" and x.type in LARGEST:
            t0 = time.perf_counter()
            refused(b, f"the structural parameter {x.name} = {LARGEST[x.type]}", b.set_status, x.name, LARGEST[x.type])
            assert time.perf_counter() - t0 < patient(HUGE_COUNT_SECONDS)
        elif x.dimensions and x.type == "Float64" and x.causality == "parameter":
            for n in HUGE:
                refused(b, f"the array {x.name} given {n} values",
                        u.fmi3SetFloat64, b.c, raw.vrs([x.valueReference]), 1, values, n)
    b.init()
    fresh.init()
    assert same(run(b, 0), run(fresh, 0)), "the instance no longer steps as a fresh one"


#: the largest value of each integer type a structural parameter may have
LARGEST = {"UInt8": 2**8 - 1, "UInt16": 2**16 - 1, "UInt32": 2**32 - 1, "UInt64": 2**64 - 1,
           "Int8": 2**7 - 1, "Int16": 2**15 - 1, "Int32": 2**31 - 1, "Int64": 2**63 - 1}


BAD_NAMES = {"invalid UTF-8": b"\xff\xfe\x80bad", "Latin-1": b"caf\xe9", "a cut UTF-8 sequence": b"motor \xe2\x82",
             "control characters": b"a\x1b[31m\x00b", "a megabyte": b"x" * (1 << 20), "empty": b""}


def _bad_instance_names(u):
    h = step_size(u)
    for what, name in BAD_NAMES.items():
        doing(f"fmi3InstantiateCoSimulation with a name of {what}")
        inst = raw.Instance3(u, name)
        logged_well(inst.log.since(0), f"an instance named with {what}")
        if not inst.c:
            assert inst.log.records, f"an instance named with {what}: NULL without a log message"
            continue
        refused(inst, f"fmi3DoStep before initialisation, named with {what}", inst.step, h, 0.0)
        inst.init()
        run(inst, 0, 2)
        inst.free()
    for what, kw in (("a NULL name", dict(name=None)), ("a NULL token", dict(token=None)),
                     ("a wrong token", dict(token=b"{00000000-0000-0000-0000-000000000000}")),
                     ("a token of invalid UTF-8", dict(token=b"\xff" * 64))):
        doing(f"fmi3InstantiateCoSimulation with {what}")
        inst = raw.Instance3(u, **kw)
        assert not inst.c, f"fmi3InstantiateCoSimulation with {what}: an instance"
        logged_well(inst.log.since(0), what)
    # no logger at all: refusals still return fmi3Error, and nothing crashes
    doing("an instance without a logger, refusing a step")
    quiet = raw.Instance3(u, b"quiet", log=None)
    assert quiet.c
    assert quiet.step(h, t=0.0) == ERROR
    quiet.free()


# --- the tests ---

@pytest.mark.parametrize("name", FMUS)
def test_a_null_instance_is_refused_by_every_function(unzipped3, name):
    isolated(_null_instance, unzipped3(name))


@pytest.mark.parametrize("name", FMUS)
def test_null_for_every_pointer_argument_is_refused(unzipped3, name):
    isolated(_null_pointers, unzipped3(name))


@pytest.mark.parametrize("name", FMUS)
def test_calls_in_the_wrong_state_are_refused(unzipped3, name):
    isolated(_wrong_state, unzipped3(name))


@pytest.mark.parametrize("name", FMUS)
def test_tampered_serialized_states_are_refused(unzipped3, name):
    other = FMUS[(FMUS.index(name) + 1) % len(FMUS)]
    isolated(_tampered_states, unzipped3(name), unzipped3(other))


@pytest.mark.parametrize("name", FMUS)
def test_huge_counts_and_bad_references_are_refused(unzipped3, name):
    isolated(_huge_counts, unzipped3(name))


@pytest.mark.parametrize("name", FMUS)
def test_bad_instance_names_and_tokens(unzipped3, name):
    isolated(_bad_instance_names, unzipped3(name))


def test_exports_every_fmi3_co_simulation_function(unzipped3):
    for name in FMUS:
        u = unzipped3(name)
        assert raw.FMI3_CS_FUNCTIONS <= u.exported, sorted(raw.FMI3_CS_FUNCTIONS - u.exported)
