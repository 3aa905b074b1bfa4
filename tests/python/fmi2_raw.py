"""The tests' FMU wrapper: direct ctypes access to an FMU's FMI 2.0 C API. Every function with its
C signature and no checks of our own, so that a test can pass NULL pointers, zero lengths, wrong
value references and calls out of sequence, and read the raw status (Unzipped, the fmi2XXX
functions); and an instance with its log and values by name (Instance: set/get assert fmi2OK,
setup/enter/exit/step/reset return the status; refused() for the calls that must fail).
The scenarios' own wrapper, on fmpy, is scenarios/cosim/fmu.py."""
from __future__ import annotations

import ctypes as C
import math
import shutil
from pathlib import Path
from urllib.parse import quote

from fmpy import extract, read_model_description
from fmpy.fmi2 import (
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

OK, WARNING, DISCARD, ERROR, FATAL, PENDING = range(6)
STATUS = {OK: "OK", WARNING: "Warning", DISCARD: "Discard", ERROR: "Error", FATAL: "Fatal", PENDING: "Pending"}
CO_SIMULATION, MODEL_EXCHANGE = 1, 0
KIND_DO_STEP, KIND_PENDING, KIND_LAST_SUCCESSFUL_TIME, KIND_TERMINATED = range(4)

comp = C.c_void_p
vr_p = C.POINTER(C.c_uint)
SIGNATURES = {
    # name: (restype, argtypes)
    "fmi2GetTypesPlatform": (C.c_char_p, []),
    "fmi2GetVersion": (C.c_char_p, []),
    "fmi2SetDebugLogging": (C.c_int, [comp, C.c_int, C.c_size_t, C.POINTER(C.c_char_p)]),
    "fmi2Instantiate": (comp, [C.c_char_p, C.c_int, C.c_char_p, C.c_char_p, C.c_void_p, C.c_int, C.c_int]),
    "fmi2FreeInstance": (None, [comp]),
    "fmi2SetupExperiment": (C.c_int, [comp, C.c_int, C.c_double, C.c_double, C.c_int, C.c_double]),
    "fmi2EnterInitializationMode": (C.c_int, [comp]),
    "fmi2ExitInitializationMode": (C.c_int, [comp]),
    "fmi2Terminate": (C.c_int, [comp]),
    "fmi2Reset": (C.c_int, [comp]),
    "fmi2GetReal": (C.c_int, [comp, vr_p, C.c_size_t, C.POINTER(C.c_double)]),
    "fmi2GetInteger": (C.c_int, [comp, vr_p, C.c_size_t, C.POINTER(C.c_int)]),
    "fmi2GetBoolean": (C.c_int, [comp, vr_p, C.c_size_t, C.POINTER(C.c_int)]),
    "fmi2GetString": (C.c_int, [comp, vr_p, C.c_size_t, C.POINTER(C.c_char_p)]),
    "fmi2SetReal": (C.c_int, [comp, vr_p, C.c_size_t, C.POINTER(C.c_double)]),
    "fmi2SetInteger": (C.c_int, [comp, vr_p, C.c_size_t, C.POINTER(C.c_int)]),
    "fmi2SetBoolean": (C.c_int, [comp, vr_p, C.c_size_t, C.POINTER(C.c_int)]),
    "fmi2SetString": (C.c_int, [comp, vr_p, C.c_size_t, C.POINTER(C.c_char_p)]),
    "fmi2GetFMUstate": (C.c_int, [comp, C.POINTER(C.c_void_p)]),
    "fmi2SetFMUstate": (C.c_int, [comp, C.c_void_p]),
    "fmi2FreeFMUstate": (C.c_int, [comp, C.POINTER(C.c_void_p)]),
    "fmi2SerializedFMUstateSize": (C.c_int, [comp, C.c_void_p, C.POINTER(C.c_size_t)]),
    "fmi2SerializeFMUstate": (C.c_int, [comp, C.c_void_p, C.c_char_p, C.c_size_t]),
    "fmi2DeSerializeFMUstate": (C.c_int, [comp, C.c_char_p, C.c_size_t, C.POINTER(C.c_void_p)]),
    "fmi2GetDirectionalDerivative": (C.c_int, [comp, vr_p, C.c_size_t, vr_p, C.c_size_t, C.POINTER(C.c_double),
                                               C.POINTER(C.c_double)]),
    "fmi2SetRealInputDerivatives": (C.c_int, [comp, vr_p, C.c_size_t, C.POINTER(C.c_int), C.POINTER(C.c_double)]),
    "fmi2GetRealOutputDerivatives": (C.c_int, [comp, vr_p, C.c_size_t, C.POINTER(C.c_int), C.POINTER(C.c_double)]),
    "fmi2DoStep": (C.c_int, [comp, C.c_double, C.c_double, C.c_int]),
    "fmi2CancelStep": (C.c_int, [comp]),
    "fmi2GetStatus": (C.c_int, [comp, C.c_int, C.POINTER(C.c_int)]),
    "fmi2GetRealStatus": (C.c_int, [comp, C.c_int, C.POINTER(C.c_double)]),
    "fmi2GetIntegerStatus": (C.c_int, [comp, C.c_int, C.POINTER(C.c_int)]),
    "fmi2GetBooleanStatus": (C.c_int, [comp, C.c_int, C.POINTER(C.c_int)]),
    "fmi2GetStringStatus": (C.c_int, [comp, C.c_int, C.POINTER(C.c_char_p)]),
}
FMI2_FUNCTIONS = frozenset(SIGNATURES)


class Unzipped:
    """An FMU extracted to a directory, with its model description and its library loaded."""

    def __init__(self, fmu: str | Path, directory: str | Path):
        self.fmu = Path(fmu)
        self.dir = Path(extract(str(fmu), unzipdir=str(directory)))
        self.md = read_model_description(str(self.fmu))
        self.id = self.md.coSimulation.modelIdentifier
        self.guid = self.md.guid
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.library = self.dir / "binaries" / "linux64" / f"{self.id}.so"
        self.dll = C.CDLL(str(self.library))
        for name, (restype, argtypes) in SIGNATURES.items():
            f = getattr(self.dll, name)
            f.restype, f.argtypes = restype, argtypes

    @property
    def resource_uri(self) -> str:
        return (self.dir / "resources").as_uri()

    def copy_to(self, directory: str | Path) -> Path:
        """A copy of the unzipped FMU at `directory` (for odd resource paths)."""
        shutil.copytree(self.dir, directory)
        return Path(directory)

    def __getattr__(self, name):  # fmi2XXX functions of the library
        if name.startswith("fmi2"):
            return getattr(self.dll, name)
        raise AttributeError(name)


class Logger:
    """fmi2CallbackFunctions with a logger that keeps (status, category, message)."""

    def __init__(self, with_logger: bool = True):
        self.records: list[tuple[int, str, str]] = []
        self.callbacks = fmi2CallbackFunctions()
        self._keep = fmi2CallbackLoggerTYPE(self._log)
        if with_logger:
            self.callbacks.logger = self._keep
        # the FMUs declare canNotUseMemoryManagementFunctions: these must never be called
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(self._never)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(self._never_free)
        self.memory_calls = 0

    def _never(self, n, size):
        self.memory_calls += 1
        return None

    def _never_free(self, p):
        self.memory_calls += 1

    def _log(self, env, instance, status, category, message):
        self.records.append((status, (category or b"").decode(), (message or b"").decode().replace("%%", "%")))

    def text(self) -> str:
        return "\n".join(f"[{STATUS.get(s, s)} {c}] {m}" for s, c, m in self.records)

    def clear(self):
        self.records.clear()


def reals(values):
    return (C.c_double * len(values))(*values)


def ints(values):
    return (C.c_int * len(values))(*values)


def vrs(values):
    return (C.c_uint * len(values))(*values)


class Instance:
    """One instance of an Unzipped FMU through the raw C API. Methods return the fmi2Status."""

    def __init__(self, fmu: Unzipped, name: str = "instance", resource_uri: str | None | type(...) = ...,
                 logger: Logger | None | type(...) = ..., logging_on: bool = False, guid: str | None = None):
        self.fmu = fmu
        self.log = Logger() if logger is ... else logger
        uri = fmu.resource_uri if resource_uri is ... else resource_uri
        callbacks = C.byref(self.log.callbacks) if self.log is not None else None
        self.c = fmu.fmi2Instantiate(name.encode(), CO_SIMULATION, (guid or fmu.guid).encode(),
                                     uri.encode() if uri is not None else None, callbacks, 0, int(logging_on))
        self.t = 0.0
        assert self.c, f"fmi2Instantiate returned NULL\n{self.log.text() if self.log else ''}"

    # --- life cycle ---
    def setup(self, start=0.0):
        self.t = start
        return self.fmu.fmi2SetupExperiment(self.c, 0, 0.0, start, 0, 0.0)

    def enter(self):
        return self.fmu.fmi2EnterInitializationMode(self.c)

    def exit(self):
        return self.fmu.fmi2ExitInitializationMode(self.c)

    def init(self, **values):
        """setup, enter, set values, exit: all must succeed."""
        assert self.setup() == OK
        assert self.enter() == OK
        self.set(**values)
        status = self.exit()
        assert status in (OK, WARNING), f"fmi2ExitInitializationMode: {STATUS[status]}\n{self.log.text()}"

    def step(self, h=1e-4, t=None):
        status = self.fmu.fmi2DoStep(self.c, self.t if t is None else t, h, 1)
        if status in (OK, WARNING) and t is None:
            self.t += h
        return status

    def terminate(self):
        return self.fmu.fmi2Terminate(self.c)

    def reset(self):
        self.t = 0.0
        return self.fmu.fmi2Reset(self.c)

    def free(self):
        if self.c:
            self.fmu.fmi2FreeInstance(self.c)
            self.c = None

    # --- values by name ---
    def set_status(self, name, value) -> int:
        v = self.fmu.vars[name]
        ref = vrs([v.valueReference])
        if v.type == "Real":
            return self.fmu.fmi2SetReal(self.c, ref, 1, reals([value]))
        if v.type == "Integer":
            return self.fmu.fmi2SetInteger(self.c, ref, 1, ints([value]))
        if v.type == "Boolean":
            return self.fmu.fmi2SetBoolean(self.c, ref, 1, ints([int(bool(value))]))
        return self.fmu.fmi2SetString(self.c, ref, 1, (C.c_char_p * 1)(None if value is None else value.encode()))

    def set(self, **values):
        for name, value in values.items():
            status = self.set_status(name, value)
            assert status == OK, f"set {name} = {value!r}: {STATUS[status]}\n{self.log.text()}"

    def get_status(self, name):
        """(status, value)"""
        v = self.fmu.vars[name]
        ref = vrs([v.valueReference])
        if v.type == "Real":
            out = reals([math.nan])
            return self.fmu.fmi2GetReal(self.c, ref, 1, out), out[0]
        if v.type in ("Integer", "Boolean"):
            out = ints([-12345])
            f = self.fmu.fmi2GetInteger if v.type == "Integer" else self.fmu.fmi2GetBoolean
            s = f(self.c, ref, 1, out)
            return s, (out[0] if v.type == "Integer" else bool(out[0]))
        out = (C.c_char_p * 1)()
        s = self.fmu.fmi2GetString(self.c, ref, 1, out)
        return s, (out[0].decode() if out[0] is not None else None)

    def get(self, *names):
        values = []
        for name in names:
            status, value = self.get_status(name)
            assert status == OK, f"get {name}: {STATUS[status]}\n{self.log.text()}"
            values.append(value)
        return values[0] if len(values) == 1 else values

    def names(self, *causalities):
        return [v.name for v in self.fmu.md.modelVariables if v.causality in causalities]

    def outputs(self):
        """Every output, as a tuple (Reals and Integers)."""
        return tuple(self.get(n) for n in self.names("output"))

    # --- FMU states ---
    def get_state(self, state=None):
        s = C.c_void_p(state)
        status = self.fmu.fmi2GetFMUstate(self.c, C.byref(s))
        assert status == OK, self.log.text()
        return s.value

    def set_state(self, state):
        return self.fmu.fmi2SetFMUstate(self.c, state)

    def free_state(self, state):
        s = C.c_void_p(state)
        return self.fmu.fmi2FreeFMUstate(self.c, C.byref(s))

    def serialize(self, state) -> bytes:
        size = C.c_size_t()
        assert self.fmu.fmi2SerializedFMUstateSize(self.c, state, C.byref(size)) == OK, self.log.text()
        buf = C.create_string_buffer(size.value)
        assert self.fmu.fmi2SerializeFMUstate(self.c, state, buf, size.value) == OK, self.log.text()
        return buf.raw

    def deserialize_status(self, data: bytes | None):
        s = C.c_void_p()
        status = self.fmu.fmi2DeSerializeFMUstate(self.c, data, len(data) if data is not None else 0, C.byref(s))
        return status, s.value

    def restore(self, data: bytes, t: float) -> None:
        """Back to the serialised state `data`, saved at time t."""
        status, state = self.deserialize_status(data)
        assert status == OK and self.set_state(state) == OK, self.log.text()
        self.t = t

    def replays(self, data: bytes, t: float, trace) -> bool:
        """trace() (a function stepping the instance, returning numbers) now, and again after
        restore(data, t): the same numbers bit for bit."""
        first = repr([float(x) for row in trace() for x in row])
        self.restore(data, t)
        return first == repr([float(x) for row in trace() for x in row])

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.free()


def refused(inst: Instance, call, *args, status: int = ERROR, match: str | None = None, **kwargs) -> str:
    """Assert that call(*args, **kwargs), a function returning an fmi2Status (an Instance method
    such as set_status, exit, step), returns `status` and that the instance's log then says
    `match`; returns that log."""
    inst.log.clear()
    got = call(*args, **kwargs)
    text = inst.log.text()
    assert got == status, f"returned {STATUS.get(got, got)}, expected {STATUS[status]}\n{text}"
    if match is not None:
        assert match in text, f"the log lacks {match!r}:\n{text}"
    return text


def resource_uri_of(path: Path) -> str:
    """file:// URI of a directory, percent-encoded (spaces, '%', non-ASCII)."""
    return "file://" + quote(str(Path(path).resolve()), safe="/")
