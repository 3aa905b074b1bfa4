"""The tests' FMI 3.0 wrapper, on fmpy's FMU3Slave: an instance of an FMI 3.0 FMU with the same
methods as fmi2_raw.Instance (setup/enter/exit/step/set/get/names, the FMU-state functions,
refused() on its log), each returning the raw status (fmpy raises on fmi3Error; the status is
taken back from its exception), so that a test or golden_traces.py runs the same inputs through
either standard. `slave` is fmpy's object and `dll` the FMU's library, for calls with arguments
fmpy would not pass (NULL pointers)."""
from __future__ import annotations

import ctypes as C
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave, fmi3FMUState, fmi3LogMessageCallback

import fmi2_raw as raw
from fmi2_raw import ERROR, OK, STATUS, WARNING, refused  # noqa: F401 (the same statuses, refused() too)


class Unzipped3:
    """An FMI 3.0 FMU extracted once: its model description and variables by name."""

    def __init__(self, fmu: str | Path, directory: str | Path):
        self.directory = str(extract(str(fmu), str(directory)))
        self.md = read_model_description(self.directory)
        assert self.md.fmiVersion == "3.0", f"{fmu} is FMI {self.md.fmiVersion}"
        self.guid = self.md.guid
        self.vars = {v.name: v for v in self.md.modelVariables}


class Log:
    """The instance's fmi3LogMessageCallback, keeping (status, category, message bytes). text()
    decodes the messages strictly: one that is not UTF-8 fails the test there (an exception in the
    callback itself would only be printed by ctypes)."""

    def __init__(self):
        self.records: list[tuple[int, bytes, bytes]] = []
        self.callback = fmi3LogMessageCallback(self._log)

    def _log(self, env, status, category, message):
        self.records.append((status, category or b"", message or b""))

    def messages(self) -> list[str]:
        return [m.decode("utf-8") for _, _, m in self.records]

    def text(self) -> str:
        return "\n".join(f"[{STATUS.get(s, s)} {c.decode('utf-8')}] {m.decode('utf-8')}" for s, c, m in self.records)

    def clear(self):
        self.records.clear()


def status_of(call, *args) -> int:
    """The fmi3Status of an fmpy call (fmpy raises for fmi3Error and fmi3Fatal)."""
    try:
        call(*args)
        return OK
    except FMICallException as e:
        return e.status


class Instance3:
    """One co-simulation instance of an Unzipped3 FMU. Methods return the fmi3Status."""

    def __init__(self, fmu: Unzipped3, name: str = "instance", logging_on: bool = False):
        self.fmu = fmu
        self.log = Log()
        self.slave = FMU3Slave(guid=fmu.guid, unzipDirectory=fmu.directory,
                               modelIdentifier=fmu.md.coSimulation.modelIdentifier, instanceName=name)
        self.slave.instantiate(loggingOn=logging_on, logMessage=self.log.callback)
        self.dll = self.slave.dll
        self.c = self.slave.component
        self.start = 0.0
        self.t = 0.0

    # --- life cycle ---
    def setup(self, start=0.0):
        """FMI 3.0 has no fmi3SetupExperiment: the start time goes with enter()."""
        self.start = self.t = start
        return OK

    def enter(self):
        return status_of(self.slave.enterInitializationMode, None, self.start, None)

    def exit(self):
        return status_of(self.slave.exitInitializationMode)

    def init(self, **values):
        assert self.enter() == OK, self.log.text()
        self.set(**values)
        status = self.exit()
        assert status in (OK, WARNING), f"fmi3ExitInitializationMode: {STATUS[status]}\n{self.log.text()}"

    def step(self, h=1e-4, t=None):
        try:
            event, terminate, early, last = self.slave.doStep(self.t if t is None else t, h, True)
        except FMICallException as e:
            return e.status
        assert not (event or terminate or early), "the FMU never asks for an event, to stop, or returns early"
        assert last == (self.t if t is None else t) + h
        if t is None:
            self.t += h
        return OK

    def terminate(self):
        return status_of(self.slave.terminate)

    def reset(self):
        self.t = 0.0
        return status_of(self.slave.reset)

    def free(self):
        if self.c:
            self.slave.fmi3FreeInstance(self.c)  # (fmpy's freeInstance would also unload the library)
            self.c = None

    # --- values by name ---
    def set_status(self, name, value) -> int:
        v = self.fmu.vars[name]
        setter = {"Float64": self.slave.setFloat64, "Int32": self.slave.setInt32, "Boolean": self.slave.setBoolean,
                  "String": self.slave.setString}[v.type]
        return status_of(setter, [v.valueReference], [value])

    set = raw.Instance.set

    def get_status(self, name):
        """(status, value)"""
        v = self.fmu.vars[name]
        getter = {"Float64": self.slave.getFloat64, "Int32": self.slave.getInt32, "Boolean": self.slave.getBoolean,
                  "String": self.slave.getString}[v.type]
        try:
            return OK, getter([v.valueReference])[0]
        except FMICallException as e:
            return e.status, None

    # by name, as fmi2_raw.Instance does it
    get = raw.Instance.get
    names = raw.Instance.names
    outputs = raw.Instance.outputs

    # --- FMU states ---
    def get_state(self):
        return self.slave.getFMUState()

    def set_state(self, state):
        return status_of(self.slave.setFMUState, state)

    def free_state(self, state):
        return status_of(self.slave.freeFMUState, state)

    def serialize(self, state) -> bytes:
        return bytes(self.slave.serializeFMUState(state))

    def deserialize_status(self, data: bytes):
        state = fmi3FMUState()
        buffer = C.create_string_buffer(data, size=len(data))
        try:
            self.slave.fmi3DeserializeFMUState(self.c, C.cast(buffer, C.POINTER(C.c_uint8)), len(data),
                                               C.byref(state))
        except FMICallException as e:
            return e.status, None
        return OK, state

    def restore(self, data: bytes, t: float) -> None:
        status, state = self.deserialize_status(data)
        assert status == OK and self.set_state(state) == OK, self.log.text()
        self.t = t

    def __enter__(self):
        return self

    def call(self, name: str, *args) -> int:
        """The raw status of the FMI 3.0 function `name` (fmpy's binding of it, without its check),
        for arguments fmpy would not pass."""
        return self.slave._functions[name](*args)

    def __exit__(self, *exc):
        self.free()
