"""The tests' FMI 3.0 wrapper, as fmi2_raw.py is the FMI 2.0 one: direct ctypes access to an FMU's
FMI 3.0 C API. Every function with its C signature (fmi3FunctionTypes.h) and no checks of our
own, so that a test can pass NULL pointers, huge counts, wrong value references and calls out of
sequence, and read the raw status (Unzipped3, the fmi3XXX functions); and an instance with its
log kept as raw bytes (Instance3), with the same methods as fmi2_raw.Instance
(setup/enter/exit/init/step/set/get/names/outputs, the FMU-state functions), each returning the
raw status, so that a test or golden_traces.py runs the same inputs through either standard; plus
FMI 3.0's own: Configuration Mode and values of any type and count (arrays).
The scenarios' own wrapper, on fmpy, is scenarios/cosim/fmu.py with scenarios/cosim/standard.py."""
from __future__ import annotations

import ctypes as C
from pathlib import Path

from fmpy import extract, read_model_description

import fmi2_raw
from fmi2_raw import DISCARD, ERROR, FATAL, OK, STATUS, WARNING, refused  # noqa: F401 (the same statuses)

#: the platform folder of FMI 3.0 (x86_64-linux)
PLATFORM = "x86_64-linux"

inst_t = C.c_void_p
vr_p = C.POINTER(C.c_uint32)
size_p = C.POINTER(C.c_size_t)
bool_p = C.POINTER(C.c_bool)
double_p = C.POINTER(C.c_double)
uint64_p = C.POINTER(C.c_uint64)
int_p = C.POINTER(C.c_int)
state_p = C.POINTER(C.c_void_p)
byte_p = C.POINTER(C.c_uint8)
LogMessage = C.CFUNCTYPE(None, C.c_void_p, C.c_int, C.c_char_p, C.c_char_p)
IntermediateUpdate = C.CFUNCTYPE(None, C.c_void_p, C.c_double, C.c_bool, C.c_bool, C.c_bool, C.c_bool, bool_p,
                                 double_p)

#: the C type of each FMI 3.0 variable type's values
VALUE_TYPES = {"Float32": C.c_float, "Float64": C.c_double, "Int8": C.c_int8, "UInt8": C.c_uint8,
               "Int16": C.c_int16, "UInt16": C.c_uint16, "Int32": C.c_int32, "UInt32": C.c_uint32,
               "Int64": C.c_int64, "UInt64": C.c_uint64, "Boolean": C.c_bool, "String": C.c_char_p}


def _get_set():
    out = {}
    for name, t in VALUE_TYPES.items():
        out[f"fmi3Get{name}"] = (C.c_int, [inst_t, vr_p, C.c_size_t, C.POINTER(t), C.c_size_t])
        out[f"fmi3Set{name}"] = (C.c_int, [inst_t, vr_p, C.c_size_t, C.POINTER(t), C.c_size_t])
    return out


SIGNATURES = {
    # name: (restype, argtypes), as fmi3FunctionTypes.h declares them
    "fmi3GetVersion": (C.c_char_p, []),
    "fmi3SetDebugLogging": (C.c_int, [inst_t, C.c_bool, C.c_size_t, C.POINTER(C.c_char_p)]),
    "fmi3InstantiateCoSimulation": (inst_t, [C.c_char_p, C.c_char_p, C.c_char_p, C.c_bool, C.c_bool, C.c_bool,
                                             C.c_bool, vr_p, C.c_size_t, C.c_void_p, LogMessage,
                                             IntermediateUpdate]),
    "fmi3FreeInstance": (None, [inst_t]),
    "fmi3EnterInitializationMode": (C.c_int, [inst_t, C.c_bool, C.c_double, C.c_double, C.c_bool, C.c_double]),
    "fmi3ExitInitializationMode": (C.c_int, [inst_t]),
    "fmi3EnterEventMode": (C.c_int, [inst_t]),
    "fmi3Terminate": (C.c_int, [inst_t]),
    "fmi3Reset": (C.c_int, [inst_t]),
    **_get_set(),
    "fmi3GetBinary": (C.c_int, [inst_t, vr_p, C.c_size_t, size_p, C.POINTER(byte_p), C.c_size_t]),
    "fmi3SetBinary": (C.c_int, [inst_t, vr_p, C.c_size_t, size_p, C.POINTER(byte_p), C.c_size_t]),
    "fmi3GetClock": (C.c_int, [inst_t, vr_p, C.c_size_t, bool_p]),
    "fmi3SetClock": (C.c_int, [inst_t, vr_p, C.c_size_t, bool_p]),
    "fmi3GetNumberOfVariableDependencies": (C.c_int, [inst_t, C.c_uint32, size_p]),
    "fmi3GetVariableDependencies": (C.c_int, [inst_t, C.c_uint32, size_p, vr_p, size_p, int_p, C.c_size_t]),
    "fmi3GetFMUState": (C.c_int, [inst_t, state_p]),
    "fmi3SetFMUState": (C.c_int, [inst_t, C.c_void_p]),
    "fmi3FreeFMUState": (C.c_int, [inst_t, state_p]),
    "fmi3SerializedFMUStateSize": (C.c_int, [inst_t, C.c_void_p, size_p]),
    "fmi3SerializeFMUState": (C.c_int, [inst_t, C.c_void_p, byte_p, C.c_size_t]),
    "fmi3DeserializeFMUState": (C.c_int, [inst_t, byte_p, C.c_size_t, state_p]),
    "fmi3GetDirectionalDerivative": (C.c_int, [inst_t, vr_p, C.c_size_t, vr_p, C.c_size_t, double_p, C.c_size_t,
                                               double_p, C.c_size_t]),
    "fmi3GetAdjointDerivative": (C.c_int, [inst_t, vr_p, C.c_size_t, vr_p, C.c_size_t, double_p, C.c_size_t,
                                           double_p, C.c_size_t]),
    "fmi3EnterConfigurationMode": (C.c_int, [inst_t]),
    "fmi3ExitConfigurationMode": (C.c_int, [inst_t]),
    "fmi3GetIntervalDecimal": (C.c_int, [inst_t, vr_p, C.c_size_t, double_p, int_p]),
    "fmi3GetIntervalFraction": (C.c_int, [inst_t, vr_p, C.c_size_t, uint64_p, uint64_p, int_p]),
    "fmi3GetShiftDecimal": (C.c_int, [inst_t, vr_p, C.c_size_t, double_p]),
    "fmi3GetShiftFraction": (C.c_int, [inst_t, vr_p, C.c_size_t, uint64_p, uint64_p]),
    "fmi3SetIntervalDecimal": (C.c_int, [inst_t, vr_p, C.c_size_t, double_p]),
    "fmi3SetIntervalFraction": (C.c_int, [inst_t, vr_p, C.c_size_t, uint64_p, uint64_p]),
    "fmi3SetShiftDecimal": (C.c_int, [inst_t, vr_p, C.c_size_t, double_p]),
    "fmi3SetShiftFraction": (C.c_int, [inst_t, vr_p, C.c_size_t, uint64_p, uint64_p]),
    "fmi3EvaluateDiscreteStates": (C.c_int, [inst_t]),
    "fmi3UpdateDiscreteStates": (C.c_int, [inst_t, bool_p, bool_p, bool_p, bool_p, bool_p, double_p]),
    "fmi3EnterStepMode": (C.c_int, [inst_t]),
    "fmi3GetOutputDerivatives": (C.c_int, [inst_t, vr_p, C.c_size_t, C.POINTER(C.c_int32), double_p, C.c_size_t]),
    "fmi3DoStep": (C.c_int, [inst_t, C.c_double, C.c_double, C.c_bool, bool_p, bool_p, bool_p, double_p]),
}
#: the functions every FMI 3.0 co-simulation FMU exports (the standard's common and co-simulation
#: functions: an FMU without a capability still exports its functions, which then refuse)
FMI3_CS_FUNCTIONS = frozenset(SIGNATURES)
#: the other interface types' functions (Model Exchange, Scheduled Execution), which an FMU may
#: export as well (refusing them where it does not implement that interface type)
SIGNATURES.update({
    "fmi3InstantiateModelExchange": (inst_t, [C.c_char_p, C.c_char_p, C.c_char_p, C.c_bool, C.c_bool, C.c_void_p,
                                              LogMessage]),
    "fmi3InstantiateScheduledExecution": (inst_t, [C.c_char_p, C.c_char_p, C.c_char_p, C.c_bool, C.c_bool,
                                                   C.c_void_p, LogMessage, C.c_void_p, C.c_void_p, C.c_void_p]),
    "fmi3ActivateModelPartition": (C.c_int, [inst_t, C.c_uint32, C.c_double]),
    "fmi3EnterContinuousTimeMode": (C.c_int, [inst_t]),
    "fmi3CompletedIntegratorStep": (C.c_int, [inst_t, C.c_bool, bool_p, bool_p]),
    "fmi3SetTime": (C.c_int, [inst_t, C.c_double]),
    "fmi3SetContinuousStates": (C.c_int, [inst_t, double_p, C.c_size_t]),
    "fmi3GetContinuousStateDerivatives": (C.c_int, [inst_t, double_p, C.c_size_t]),
    "fmi3GetEventIndicators": (C.c_int, [inst_t, double_p, C.c_size_t]),
    "fmi3GetContinuousStates": (C.c_int, [inst_t, double_p, C.c_size_t]),
    "fmi3GetNominalsOfContinuousStates": (C.c_int, [inst_t, double_p, C.c_size_t]),
    "fmi3GetNumberOfEventIndicators": (C.c_int, [inst_t, size_p]),
    "fmi3GetNumberOfContinuousStates": (C.c_int, [inst_t, size_p]),
})


class Unzipped3:
    """An FMI 3.0 FMU extracted to a directory, with its model description and its library loaded."""

    def __init__(self, fmu: str | Path, directory: str | Path):
        self.fmu = Path(fmu)
        self.dir = Path(extract(str(fmu), unzipdir=str(directory)))
        self.md = read_model_description(str(self.fmu))
        assert self.md.fmiVersion == "3.0", f"{fmu} is an FMI {self.md.fmiVersion} FMU"
        self.id = self.md.coSimulation.modelIdentifier
        self.token = self.guid = self.md.guid  # fmpy keeps the instantiationToken as guid
        self.directory = str(self.dir)
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.library = self.dir / "binaries" / PLATFORM / f"{self.id}.so"
        self.dll = C.CDLL(str(self.library))
        self.exported = {name for name in SIGNATURES if hasattr(self.dll, name)}
        for name in self.exported:
            f = getattr(self.dll, name)
            f.restype, f.argtypes = SIGNATURES[name]

    @property
    def resource_path(self) -> str:
        """fmi3InstantiateCoSimulation's resourcePath: the resources folder, with a trailing slash."""
        return str(self.dir / "resources") + "/"

    def __getattr__(self, name):  # fmi3XXX functions of the library
        if name.startswith("fmi3"):
            return getattr(self.dll, name)
        raise AttributeError(name)


class Log:
    """A logMessage callback keeping (status, category, message) as the FMU passed them: raw
    bytes, so that a test can check them for valid UTF-8 and length. messages() and text() decode
    them strictly: a message that is not UTF-8 fails the test there (an exception in the callback
    itself would only be printed by ctypes)."""

    def __init__(self):
        self.records: list[tuple[int, bytes, bytes]] = []
        self.callback = LogMessage(self._log)

    def _log(self, env, status, category, message):
        self.records.append((status, category or b"", message or b""))

    def messages(self) -> list[str]:
        return [m.decode("utf-8") for _, _, m in self.records]

    def text(self) -> str:
        return "\n".join(f"[{STATUS.get(s, s)} {c.decode('utf-8')}] {m.decode('utf-8')}" for s, c, m in self.records)

    def since(self, n: int) -> list[bytes]:
        """The messages logged after the first n."""
        return [m for _, _, m in self.records[n:]]

    def clear(self):
        self.records.clear()


def array(ctype, values):
    return (ctype * len(values))(*values)


def vrs(values):
    return array(C.c_uint32, values)


def _kind(v) -> str:
    """The FMI 3.0 type whose Get and Set take v's values (an Enumeration's are Int64)."""
    return v.type if v.type != "Enumeration" else "Int64"


class Instance3:
    """One co-simulation instance of an Unzipped3 FMU through the raw C API. Methods return the
    fmi3Status; `c` is the fmi3Instance (None if instantiation returned NULL)."""

    def __init__(self, fmu: Unzipped3, name: str | bytes | None = b"instance", token: bytes | None = ...,
                 resource_path: bytes | None = ..., logging_on: bool = False, log: Log | None = ...):
        self.fmu = fmu
        self.dll = fmu.dll
        self.log = Log() if log is ... else log
        self.start = self.t = 0.0
        callback = self.log.callback if self.log is not None else LogMessage()
        self.c = fmu.fmi3InstantiateCoSimulation(
            name.encode() if isinstance(name, str) else name, fmu.token.encode() if token is ... else token,
            fmu.resource_path.encode() if resource_path is ... else resource_path,
            False, logging_on, False, False, None, 0, None, callback, IntermediateUpdate())
        # fmi3DoStep's outputs
        self.event, self.terminate_requested, self.early, self.last = C.c_bool(), C.c_bool(), C.c_bool(), C.c_double()

    # --- life cycle ---
    def setup(self, start: float = 0.0):
        """FMI 3.0 has no fmi3SetupExperiment: the start time goes with enter()."""
        self.start = self.t = start
        return OK

    def enter(self, start: float | None = None):
        if start is not None:
            self.setup(start)
        return self.fmu.fmi3EnterInitializationMode(self.c, False, 0.0, self.start, False, 0.0)

    def exit(self):
        return self.fmu.fmi3ExitInitializationMode(self.c)

    def init(self, **values):
        """Enter Initialization Mode, set values by name, exit: all must succeed."""
        assert self.enter() == OK, self.log.text()
        self.set(**values)
        status = self.exit()
        assert status in (OK, WARNING), f"fmi3ExitInitializationMode: {STATUS[status]}\n{self.log.text()}"

    def step(self, h: float = 1e-4, t: float | None = None):
        t0 = self.t if t is None else t
        status = self.fmu.fmi3DoStep(self.c, t0, h, True, C.byref(self.event), C.byref(self.terminate_requested),
                                     C.byref(self.early), C.byref(self.last))
        if status in (OK, WARNING):
            assert not (self.event or self.terminate_requested or self.early), \
                "the FMU never asks for an event, to stop, or returns early"
            assert self.last.value == t0 + h
            if t is None:
                self.t += h
        return status

    def terminate(self):
        return self.fmu.fmi3Terminate(self.c)

    def reset(self):
        self.t = 0.0
        return self.fmu.fmi3Reset(self.c)

    def free(self):
        if self.c:
            self.fmu.fmi3FreeInstance(self.c)
            self.c = None

    def enter_configuration(self):
        return self.fmu.fmi3EnterConfigurationMode(self.c)

    def exit_configuration(self):
        return self.fmu.fmi3ExitConfigurationMode(self.c)

    # --- values by name: scalars as fmi2_raw.Instance has them ---
    def set_status(self, name: str, value) -> int:
        v = self.fmu.vars[name]
        t = VALUE_TYPES[_kind(v)]
        x = value.encode() if t is C.c_char_p else value
        return getattr(self.fmu, f"fmi3Set{_kind(v)}")(self.c, vrs([v.valueReference]), 1, array(t, [x]), 1)

    set = fmi2_raw.Instance.set

    def get_status(self, name: str):
        """(status, value)"""
        v = self.fmu.vars[name]
        out = (VALUE_TYPES[_kind(v)] * 1)()
        status = getattr(self.fmu, f"fmi3Get{_kind(v)}")(self.c, vrs([v.valueReference]), 1, out, 1)
        value = out[0].decode() if v.type == "String" and out[0] is not None else out[0]
        return status, value

    get = fmi2_raw.Instance.get
    names = fmi2_raw.Instance.names
    outputs = fmi2_raw.Instance.outputs

    def float64_outputs(self) -> list[float]:
        """Every Float64 output's value (the model description's order), read with one call."""
        names = [v for v in self.fmu.md.modelVariables if v.causality == "output" and v.type == "Float64"]
        out = (C.c_double * len(names))()
        status = self.fmu.fmi3GetFloat64(self.c, vrs([v.valueReference for v in names]), len(names), out, len(names))
        assert status == OK, self.log.text()
        return list(out)

    # --- values of any type and count (arrays): one Get or Set of the variables `names` ---
    def set_values(self, kind: str, names, values) -> int:
        refs = [self.fmu.vars[n].valueReference for n in names]
        return getattr(self.fmu, f"fmi3Set{kind}")(self.c, vrs(refs), len(refs), array(VALUE_TYPES[kind], values),
                                                    len(values))

    def get_values(self, kind: str, names, n_values: int) -> list:
        refs = [self.fmu.vars[n].valueReference for n in names]
        out = (VALUE_TYPES[kind] * n_values)()
        status = getattr(self.fmu, f"fmi3Get{kind}")(self.c, vrs(refs), len(refs), out, n_values)
        assert status == OK, f"fmi3Get{kind} {names}: {STATUS.get(status, status)}\n{self.log.text()}"
        return list(out)

    # --- FMU states ---
    def get_state_status(self) -> tuple[int, C.c_void_p]:
        s = C.c_void_p()
        return self.fmu.fmi3GetFMUState(self.c, C.byref(s)), s

    def get_state(self) -> C.c_void_p:
        status, s = self.get_state_status()
        assert status == OK, self.log.text()
        return s

    def set_state(self, state) -> int:
        return self.fmu.fmi3SetFMUState(self.c, state)

    def free_state(self, state) -> int:
        s = C.c_void_p(state.value if isinstance(state, C.c_void_p) else state)
        return self.fmu.fmi3FreeFMUState(self.c, C.byref(s))

    def serialize(self, state: C.c_void_p) -> bytes:
        n = C.c_size_t()
        assert self.fmu.fmi3SerializedFMUStateSize(self.c, state, C.byref(n)) == OK, self.log.text()
        buf = (C.c_uint8 * n.value)()
        assert self.fmu.fmi3SerializeFMUState(self.c, state, buf, n.value) == OK, self.log.text()
        return bytes(buf)

    def deserialize_status(self, blob: bytes) -> tuple[int, C.c_void_p]:
        s = C.c_void_p()
        buf = (C.c_uint8 * max(1, len(blob))).from_buffer_copy(blob.ljust(1, b"\0"))
        return self.fmu.fmi3DeserializeFMUState(self.c, buf, len(blob), C.byref(s)), s

    def restore(self, data: bytes, t: float) -> None:
        """Back to the serialised state `data`, saved at time t."""
        status, state = self.deserialize_status(data)
        assert status == OK and self.set_state(state) == OK, self.log.text()
        self.t = t

    def call(self, name: str, *args) -> int:
        """The raw status of the FMI 3.0 function `name`, for arguments a method would not pass."""
        return getattr(self.fmu, name)(*args)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.free()
