"""The two FMI standards a co-simulation FMU may speak, FMI 2.0 and FMI 3.0, behind one small
interface: everything Fmu and DriveFmu do that differs between them is here, chosen once from the
model description's fmiVersion (`for_version`).

What differs: the instance's creation (fmi2Instantiate, fmi3InstantiateCoSimulation) and its
logger's signature; the start (fmi2SetupExperiment + fmi2EnterInitializationMode, or
fmi3EnterInitializationMode with the experiment in it); the names of the variable types
(Real/Integer, Float64/Int32/Int64) and of their Set/Get functions, which in FMI 3.0 also take
the number of values; fmi3Boolean is a C bool where fmi2Boolean is an int; fmi3DoStep reports a
request to end the simulation through an argument, which is returned here as FMI 2.0 reports it,
fmi2Discard; and the FMU-state functions' spelling (getFMUstate, getFMUState).

The per-step functions (`setter`, `getter`, `do_step`) take (instance, value references, count,
values) and return the raw status, so the per-step paths keep their ctypes arrays made once."""
from __future__ import annotations

import ctypes as C

from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.fmi3 import FMU3Slave

#: the status values the two standards share (fmi2FunctionTypes.h, fmi3FunctionTypes.h)
OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4


class Fmi2:
    """FMI 2.0 co-simulation (fmpy's FMU2Slave)."""

    version = "2.0"
    #: the prefix of its function names (what messages call a function)
    PREFIX = "fmi2"
    #: a variable's type in the model description -> the Set/Get function's type, the value's
    #: conversion and its C type
    KINDS = {"Real": ("Real", float, C.c_double), "Integer": ("Integer", int, C.c_int),
             "Enumeration": ("Integer", int, C.c_int), "Boolean": ("Boolean", bool, C.c_int),
             "String": ("String", str, None)}
    #: what a neutral name asks for (Fmu.read's "Real", "Integer", "Boolean")
    NEUTRAL = {"Real": "Real", "Integer": "Integer", "Boolean": "Boolean"}
    #: the function that ends Initialization Mode
    EXIT_INITIALIZATION = "fmi2ExitInitializationMode"

    def __init__(self, md, unzip_dir: str, instance_name: str, logging_on: bool, log):
        """log(status, category, message): every message the FMU logs (bytes or None)."""
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip_dir, modelIdentifier=md.coSimulation.modelIdentifier,
                               instanceName=instance_name)
        self._logger = fmi2CallbackLoggerTYPE(lambda env, inst, status, category, message:
                                              log(status, category, message))  # alive with the instance
        cb = fmi2CallbackFunctions()
        cb.logger, cb.allocateMemory, cb.freeMemory = self._logger, defaultCallbacks.allocateMemory, \
            defaultCallbacks.freeMemory
        self._cb = cb
        self.slave.instantiate(loggingOn=logging_on, callbacks=cb)
        self.dll, self.c = self.slave.dll, self.slave.component
        self._do_step = self.dll.fmi2DoStep

    def start_calls(self) -> tuple:
        """(function, arguments) that take a new instance into Initialization Mode at t = 0."""
        return (("fmi2SetupExperiment", (0, 0.0, 0.0, 0, 0.0)), ("fmi2EnterInitializationMode", ()))

    def setter(self, kind: str):
        """f(instance, vrs, n, values) -> status: fmi2Set<kind>."""
        return getattr(self.dll, f"fmi2Set{kind}")

    def getter(self, kind: str):
        """f(instance, vrs, n, values) -> status: fmi2Get<kind>."""
        return getattr(self.dll, f"fmi2Get{kind}")

    def do_step(self, c, t: float, h: float) -> int:
        return self._do_step(c, t, h, 1)

    def get_state(self):
        return self.slave.getFMUstate()

    def set_state(self, state) -> None:
        self.slave.setFMUstate(state)

    def free_state(self, state) -> None:
        self.slave.freeFMUstate(state)


class Fmi3(Fmi2):
    """FMI 3.0 co-simulation (fmpy's FMU3Slave)."""

    version = "3.0"
    PREFIX = "fmi3"
    KINDS = {"Float64": ("Float64", float, C.c_double), "Float32": ("Float32", float, C.c_float),
             **{k: (k, int, t) for k, t in (("Int8", C.c_int8), ("UInt8", C.c_uint8), ("Int16", C.c_int16),
                                            ("UInt16", C.c_uint16), ("Int32", C.c_int32), ("UInt32", C.c_uint32),
                                            ("Int64", C.c_int64), ("UInt64", C.c_uint64))},
             "Enumeration": ("Int64", int, C.c_int64), "Boolean": ("Boolean", bool, C.c_bool),
             "String": ("String", str, None)}
    NEUTRAL = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
    EXIT_INITIALIZATION = "fmi3ExitInitializationMode"

    def __init__(self, md, unzip_dir: str, instance_name: str, logging_on: bool, log):
        self.slave = FMU3Slave(guid=md.guid, unzipDirectory=unzip_dir, modelIdentifier=md.coSimulation.modelIdentifier,
                               instanceName=instance_name)
        # fmpy wraps the function in an fmi3LogMessageCallback and keeps it as long as the instance
        self.slave.instantiate(loggingOn=logging_on,
                               logMessage=lambda env, status, category, message: log(status, category, message))
        self.dll, self.c = self.slave.dll, self.slave.component
        self._do_step = self.dll.fmi3DoStep
        # fmi3DoStep's outputs, made once
        self._event, self._terminate, self._early, self._last = C.c_bool(), C.c_bool(), C.c_bool(), C.c_double()

    def start_calls(self) -> tuple:
        # (toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime)
        return (("fmi3EnterInitializationMode", (False, 0.0, 0.0, False, 0.0)),)

    def setter(self, kind: str):
        f = getattr(self.dll, f"fmi3Set{kind}")
        return lambda c, vrs, n, values: f(c, vrs, n, values, n)  # scalars: as many values as references

    def getter(self, kind: str):
        f = getattr(self.dll, f"fmi3Get{kind}")
        return lambda c, vrs, n, values: f(c, vrs, n, values, n)

    def do_step(self, c, t: float, h: float) -> int:
        status = self._do_step(c, t, h, True, C.byref(self._event), C.byref(self._terminate), C.byref(self._early),
                               C.byref(self._last))
        # an FMU that asks to end the simulation: as FMI 2.0 says it (fmi2Discard, fmi2Terminated)
        return max(status, DISCARD) if self._terminate.value else status

    def get_state(self):
        return self.slave.getFMUState()

    def set_state(self, state) -> None:
        self.slave.setFMUState(state)

    def free_state(self, state) -> None:
        self.slave.freeFMUState(state)


STANDARDS = {s.version: s for s in (Fmi2, Fmi3)}


def for_version(fmi_version: str):
    """The standard of a model description's fmiVersion ("2.0", "3.0", "3.0-beta..." is no 3.0);
    None for one this project does not speak."""
    return STANDARDS.get(fmi_version)
