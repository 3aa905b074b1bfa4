"""The co-simulation master for drive cycles: the units of the drive's coupling description
(fmu_src/coupling/ipmsm_drive.coupling: IpmsmController + IpmsmPlant, Jacobi-coupled at a fixed
communication step h, default 100 us), driven by a slower caller (the vehicle side) that holds
the external inputs over each call of `advance`.

    from scenarios.cosim.master import DriveCosim
    with DriveCosim("build/fmu/IpmsmController.fmu", "build/fmu/IpmsmPlant.fmu", w_m=100.0) as cosim:
        r = cosim.advance(100, T_ref=120.0, w_m=100.0, u_dc=355.0, T_magnet=353.15, T_winding=373.15)
        r.mean.T_shaft, r.end.i_q, r.t, r.k      # an AdvanceResult; mean and end are Samples

One interface, two backends that make the same FMI calls in the same order (so their results
are bit-identical, tests/python/test_master.py checks it), both reading the coupling by name:
- "native": build/lib/libipmsm_cosim.so (scenarios/native/cosim.cpp) via ctypes; the loop runs
  in C++. For drive cycles.
- "fmpy": the same loop in Python (`_FmpyBackend`) on the FMUs' functions as loaded by fmpy's
  FMU2Slave. The reference, and the fallback when the library is not built.
- "auto": native if the library exists, else fmpy.

The calls (the description states the semantics):
- set-up: fmi2Instantiate of every unit; fmi2SetupExperiment + fmi2EnterInitializationMode of
  every unit; the parameters; then unit by unit in the description's order (the plant first):
  one fmi2SetReal of its external inputs and of its connected inputs from the units already
  initialised (the controller gets the plant's initial current: a flying start),
  fmi2ExitInitializationMode, one fmi2GetReal of its connected outputs.
- advance(n): one fmi2SetReal per unit of its external inputs; then n steps, each: one
  fmi2SetReal per (receiving, sending) unit of the connected inputs (the values read after the
  previous step), fmi2DoStep(k h, h) of every unit, k += 1, fmi2GetReal (connected outputs, then
  the Sample's Reals) and fmi2GetInteger (the Sample's Integers) of every unit.

Errors: any FMI call returning fmi2Error/fmi2Fatal raises CosimError naming the FMU, the
function, the time and step, with the FMU's log message. A refused external input (NaN,
u_dc <= 0, out of range) leaves k as it was: fix it and call again. A failure while stepping
stops the master (the units are then out of step): close it.
"""
from __future__ import annotations

import ctypes
import logging
import math
import os
import shutil
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from ctypes import POINTER, Structure, c_char_p, c_double, c_int, c_longlong, c_size_t, c_uint, c_void_p
from dataclasses import dataclass, fields
from enum import IntEnum
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description

from scenarios.cosim.coupling import DRIVE, Coupling

ROOT = Path(__file__).resolve().parents[2]
LOG = logging.getLogger("scenarios.cosim.master")


class Status(IntEnum):
    """fmi2Status (fmi2FunctionTypes.h)."""
    fmi2OK = 0
    fmi2Warning = 1
    fmi2Discard = 2
    fmi2Error = 3
    fmi2Fatal = 4
    fmi2Pending = 5


def _status_name(status: int) -> str:
    try:
        return Status(status).name
    except ValueError:
        return "an unknown fmi2Status"


@dataclass(slots=True)  # (not frozen: a frozen dataclass is ~7x slower to build, once per advance)
class DriveInputs:
    """The external inputs of the drive, held over an `advance` (the vehicle side's). Each feeds
    the inputs the coupling description names for it (w_m -> controller.w_m, plant.w_m). The
    fields, in this order, are those of ipmsm_cosim_inputs (scenarios/native/cosim.h)."""
    T_ref: float      # N.m, torque command
    w_m: float        # rad/s, mechanical speed
    u_dc: float       # V, DC-link voltage
    T_magnet: float   # K
    T_winding: float  # K


class _CInputs(Structure):
    _fields_ = [(f.name, c_double) for f in fields(DriveInputs)]


@dataclass(slots=True)
class Sample:
    """The drive's outputs at one instant, or their means over the steps of one `advance`.
    SI units, named as in the contract (INTERFACE.md): the plant's T_shaft, T_e, P_elec, P_mech,
    P_cu, P_fe, i_d, i_q; i_abs = sqrt(i_d^2 + i_q^2) and i_abs_sq = i_d^2 + i_q^2 of the plant's
    currents (the mean of i_abs_sq is what the inverter's conduction loss needs); the
    controller's T_cmd, T_max, region, iterations, u_ratio (Integers as floats: a mean of region
    is the time share weighted region, rarely useful). The means of the powers and torques are
    exact (the plant's integrals), the others the means of the values after each step."""
    T_shaft: float
    T_e: float
    P_elec: float
    P_mech: float
    P_cu: float
    P_fe: float
    i_d: float
    i_q: float
    i_abs: float
    i_abs_sq: float
    T_cmd: float
    T_max: float
    region: float
    iterations: float
    u_ratio: float


@dataclass(slots=True)
class AdvanceResult:
    """What one `DriveCosim.advance` returns: per output, the mean over its steps of the value
    after each step, and the value after the last step; the time t = k h and step index k
    after it; the number of trace rows written."""
    mean: Sample
    end: Sample
    t: float
    k: int
    rows: int


# Where each field of Sample comes from: "ROLE.VARIABLE", or "|i|" and "|i|^2" of the plant's
# i_d, i_q (computed by the master; cosim.h).
SAMPLE_SOURCES = {
    "T_shaft": "plant.T_shaft", "T_e": "plant.T_e", "P_elec": "plant.P_elec", "P_mech": "plant.P_mech",
    "P_cu": "plant.P_cu", "P_fe": "plant.P_fe", "i_d": "plant.i_d", "i_q": "plant.i_q", "i_abs": "|i|",
    "i_abs_sq": "|i|^2", "T_cmd": "controller.T_cmd", "T_max": "controller.T_max", "region": "controller.region",
    "iterations": "controller.iterations", "u_ratio": "controller.u_ratio",
}
SAMPLE_FIELDS = tuple(f.name for f in fields(Sample))
# The plant's integrals since the start (exact over each step): advance()'s means of P_elec,
# P_mech, P_cu, P_fe, T_e and T_shaft are their increases over it, divided by its duration.
PLANT_INTEGRALS = ("E_elec", "E_mech", "E_cu", "E_fe", "T_e_impulse")
_CURRENT_PROBES = ("|i|", "|i|^2")


class CosimError(RuntimeError):
    """An FMI call failed (the message names the FMU, the function, the time and quotes the
    FMU's log), or the master was used wrongly."""


def default_library(controller_fmu: str | Path | None = None) -> Path:
    """libipmsm_cosim.so: $IPMSM_COSIM_LIB, else the one of the build the controller FMU comes
    from (<build>/fmu/X.fmu -> <build>/lib/), else build/lib/ of this repository."""
    env = os.environ.get("IPMSM_COSIM_LIB")
    if env:
        return Path(env)
    if controller_fmu is not None:
        candidate = Path(controller_fmu).resolve().parent.parent / "lib" / "libipmsm_cosim.so"
        if candidate.exists():
            return candidate
    return ROOT / "build" / "lib" / "libipmsm_cosim.so"


def _when(k: int, h: float) -> str:
    return f" at t = {k * h:.9g} s (step k = {k})"


class _Unit:
    """One FMU of the coupling: its role, model description and extracted folder."""

    def __init__(self, role: str, model_identifier: str, path: str | Path, instance_name: str):
        self.role = role
        self.path = Path(path)
        self.md = read_model_description(str(self.path))
        self.identifier = self.md.coSimulation.modelIdentifier
        if self.identifier != model_identifier:
            raise CosimError(f"the {role} must be {model_identifier}, {self.path} is {self.identifier}")
        self.instance_name = instance_name
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.dir = extract(str(self.path))
        self.pending: list[tuple[int, str, str]] = []  # (status, category, message) of the current call

    def variable(self, name: str):
        try:
            return self.vars[name]
        except KeyError:
            raise CosimError(f"{self.identifier} has no variable {name!r}") from None

    def real_vr(self, name: str) -> int:
        v = self.variable(name)
        if v.type != "Real":
            raise CosimError(f"{self.identifier}.{name} is not a Real")
        return v.valueReference

    def describe(self) -> str:
        return f"{self.identifier} ({self.role}, instance '{self.instance_name}')"

    def remove_dir(self) -> None:
        if self.dir:
            shutil.rmtree(self.dir, ignore_errors=True)
            self.dir = None


# --------------------------------------------------------------------------------------------
# Backends: the same operations, the same FMI calls in the same order.

class _NativeBackend:
    """libipmsm_cosim (scenarios/native/cosim.h) through ctypes."""
    _LOG_FN = ctypes.CFUNCTYPE(None, c_void_p, c_char_p, c_char_p, c_int, c_char_p, c_char_p)
    _libs: dict[str, ctypes.CDLL] = {}

    def __init__(self, library: Path, coupling: Coupling, h: float, log: Callable):
        self.lib = self._load(Path(library))
        self._log_cb = self._LOG_FN(lambda user, role, inst, status, cat, msg:
                                    log(role.decode(), status, (cat or b"").decode(errors="replace"),
                                        (msg or b"").decode(errors="replace")))
        self.m = self.lib.ipmsm_cosim_new(coupling.text.encode(), h, self._log_cb, None)
        if not self.m:
            raise CosimError(f"ipmsm_cosim_new refused h = {h!r}")
        self._inputs = _CInputs()

    @classmethod
    def _load(cls, library: Path) -> ctypes.CDLL:
        key = str(library.resolve()) if library.exists() else str(library)
        if key in cls._libs:
            return cls._libs[key]
        if not library.exists():
            raise FileNotFoundError(f"{library} is missing: build it (cmake --build build) or use backend='fmpy'")
        lib = ctypes.CDLL(key)
        P, S = c_void_p, c_char_p
        u_p, d_p, i_p, in_p = POINTER(c_uint), POINTER(c_double), POINTER(c_int), POINTER(_CInputs)
        sig = {
            "ipmsm_cosim_new": (P, [S, c_double, cls._LOG_FN, P]),
            "ipmsm_cosim_free": (None, [P]),
            "ipmsm_cosim_error": (S, [P]),
            "ipmsm_cosim_instantiate": (c_int, [P, S, S, S, c_int]),
            "ipmsm_cosim_enter_initialization": (c_int, [P]),
            "ipmsm_cosim_set_real": (c_int, [P, S, c_size_t, u_p, d_p]),
            "ipmsm_cosim_set_integer": (c_int, [P, S, c_size_t, u_p, i_p]),
            "ipmsm_cosim_set_boolean": (c_int, [P, S, c_size_t, u_p, i_p]),
            "ipmsm_cosim_set_string": (c_int, [P, S, c_size_t, u_p, POINTER(c_char_p)]),
            "ipmsm_cosim_get_real": (c_int, [P, S, c_size_t, u_p, d_p]),
            "ipmsm_cosim_get_integer": (c_int, [P, S, c_size_t, u_p, i_p]),
            "ipmsm_cosim_initialize": (c_int, [P, in_p]),
            "ipmsm_cosim_probes": (c_int, [P, c_size_t, POINTER(c_char_p)]),
            "ipmsm_cosim_advance": (c_longlong, [P, c_longlong, in_p, d_p, d_p, P, c_longlong, c_longlong]),
            "ipmsm_cosim_step_index": (c_longlong, [P]),
        }
        for name, (res, args) in sig.items():
            f = getattr(lib, name)
            f.restype, f.argtypes = res, args
        cls._libs[key] = lib
        return lib

    def _check(self, rc: int) -> None:
        if rc < 0:
            raise CosimError(self.lib.ipmsm_cosim_error(self.m).decode(errors="replace"))

    def instantiate(self, u: _Unit, logging_on: bool) -> None:
        self._check(self.lib.ipmsm_cosim_instantiate(self.m, u.role.encode(), str(u.dir).encode(),
                                                     u.instance_name.encode(), int(logging_on)))

    def enter_initialization(self) -> None:
        self._check(self.lib.ipmsm_cosim_enter_initialization(self.m))

    def set(self, u: _Unit, kind: str, vrs: Sequence[int], values: Sequence) -> None:
        n = len(vrs)
        vr = (c_uint * n)(*vrs)
        role = u.role.encode()
        if kind == "Real":
            self._check(self.lib.ipmsm_cosim_set_real(self.m, role, n, vr, (c_double * n)(*values)))
        elif kind == "Integer":
            self._check(self.lib.ipmsm_cosim_set_integer(self.m, role, n, vr, (c_int * n)(*values)))
        elif kind == "Boolean":
            self._check(self.lib.ipmsm_cosim_set_boolean(self.m, role, n, vr, (c_int * n)(*values)))
        else:
            self._check(self.lib.ipmsm_cosim_set_string(self.m, role, n, vr,
                                                        (c_char_p * n)(*[v.encode() for v in values])))

    def get_reals(self, u: _Unit, vrs, out) -> None:
        """The Real variables vrs (a c_uint array) into out (a c_double array of the same length)."""
        self._check(self.lib.ipmsm_cosim_get_real(self.m, u.role.encode(), len(vrs), vrs, out))

    def get(self, u: _Unit, kind: str, vr: int) -> float | int:
        if kind == "Real":
            out = c_double()
            self._check(self.lib.ipmsm_cosim_get_real(self.m, u.role.encode(), 1, (c_uint * 1)(vr), ctypes.byref(out)))
        else:
            out = c_int()
            self._check(self.lib.ipmsm_cosim_get_integer(self.m, u.role.encode(), 1, (c_uint * 1)(vr),
                                                         ctypes.byref(out)))
        return out.value

    def initialize(self, start: DriveInputs) -> None:
        c_start = _CInputs(**{f.name: getattr(start, f.name) for f in fields(DriveInputs)})
        self._check(self.lib.ipmsm_cosim_initialize(self.m, ctypes.byref(c_start)))

    def probes(self, names: Sequence[str]) -> None:
        n = len(names)
        self._check(self.lib.ipmsm_cosim_probes(self.m, n, (c_char_p * n)(*[s.encode() for s in names])))
        self._n = n
        self._mean = (c_double * max(n, 1))()
        self._end = (c_double * max(n, 1))()

    def advance(self, n_steps: int, inputs: DriveInputs, trace, decimation: int):
        x = self._inputs
        x.T_ref, x.w_m, x.u_dc, x.T_magnet = inputs.T_ref, inputs.w_m, inputs.u_dc, inputs.T_magnet
        x.T_winding = inputs.T_winding
        if trace is None:
            rows = self.lib.ipmsm_cosim_advance(self.m, n_steps, x, self._mean, self._end, None, 0, 0)
        else:
            rows = self.lib.ipmsm_cosim_advance(self.m, n_steps, x, self._mean, self._end, trace.ctypes.data,
                                                trace.shape[0], decimation)
        if rows < 0:
            raise CosimError(self.lib.ipmsm_cosim_error(self.m).decode(errors="replace"))
        return self._mean[:self._n], self._end[:self._n], rows

    @property
    def k(self) -> int:
        return self.lib.ipmsm_cosim_step_index(self.m)

    def close(self) -> None:
        if self.m:
            self.lib.ipmsm_cosim_free(self.m)
            self.m = None


class _FmpyUnit:
    """What the fmpy loop holds of one unit: its FMU2Slave, FMI functions and read buffers."""

    def __init__(self, u: _Unit):
        self.u = u
        self.fmu = None
        self.initialised = False
        self.fatal = False
        self.external_vr: list[int] = []
        self.external_names: list[str] = []    # the external inputs' names (DriveInputs fields)
        self.external_targets: list[str] = []  # the variables they feed, for messages
        self.read_real: list[int] = []  # connected outputs first (n_connected), then Real probes
        self.read_int: list[int] = []
        self.n_connected = 0
        self.real = (c_double * 0)()
        self.integer = (c_int * 0)()


class _FmpyBackend:
    """The master in Python, on the FMUs' C functions as fmpy's FMU2Slave loads them: the
    reference for the native one, call for call."""

    def __init__(self, coupling: Coupling, h: float, log: Callable,
                 step_times: Callable[[int], tuple[float, float]] | None = None):
        from fmpy.fmi2 import defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
        self.coupling = coupling
        self.h = h
        self._log = log
        self._step_times = step_times
        self.units: list[_FmpyUnit] = []
        self.coupled = False
        self.stopped = False
        self._k = 0

        def logger(env, instance, status, category, message):
            index = (env or 0) - 1
            if 0 <= index < len(self.units) and len(self.units[index].u.pending) < 1000:
                # the FMU doubles '%' for printf-style loggers: undo it as printf would
                text = (message or b"").decode(errors="replace").replace("%%", "%")
                self.units[index].u.pending.append((status, (category or b"").decode(errors="replace"), text))

        self._logger = fmi2CallbackLoggerTYPE(logger)
        self._callbacks = []
        for index in range(len(coupling.units)):
            cb = fmi2CallbackFunctions()
            cb.logger = self._logger
            cb.allocateMemory = defaultCallbacks.allocateMemory
            cb.freeMemory = defaultCallbacks.freeMemory
            cb.componentEnvironment = index + 1
            self._callbacks.append(cb)

    # -- the status check, as the native master's
    def _flush(self, u: _Unit, quoted: bool = False) -> None:
        for status, category, message in u.pending:
            if not (quoted and status >= Status.fmi2Warning):
                self._log(u.role, status, category, message)
        u.pending.clear()

    def _failure(self, u: _Unit, what: str) -> str:
        messages = [m for s, _, m in u.pending if s >= Status.fmi2Warning]
        self._flush(u, quoted=True)
        quoted = (": " + "; ".join(messages)) if messages else " (the FMU logged no message)"
        return f"{u.describe()}: {what}{quoted}"

    def _check(self, f: _FmpyUnit, status: int, function: str, when: str = "") -> None:
        if status <= Status.fmi2Warning:
            if f.u.pending:
                self._flush(f.u)
            return
        if status == Status.fmi2Fatal:
            f.fatal = True
        raise CosimError(self._failure(f.u, f"{function}{when} returned {_status_name(status)}"))

    def _unit(self, u: _Unit) -> _FmpyUnit:
        f = self.units[self.coupling.unit_index(u.role)]
        if f.fmu is None:
            raise CosimError(f"the {u.role} is not instantiated")
        if f.fatal:
            raise CosimError(f"{u.identifier} reported fmi2Fatal earlier: it can only be freed")
        return f

    def _when(self) -> str:
        return _when(self._k, self.h) if self.coupled else ""

    def instantiate(self, u: _Unit, logging_on: bool) -> None:
        from fmpy.fmi2 import FMU2Slave
        if not self.units:
            self.units = [None] * len(self.coupling.units)
        index = self.coupling.unit_index(u.role)
        f = self.units[index] = _FmpyUnit(u)
        fmu = FMU2Slave(guid=u.md.guid, unzipDirectory=u.dir, modelIdentifier=u.identifier,
                        instanceName=u.instance_name)
        try:
            fmu.instantiate(callbacks=self._callbacks[index], loggingOn=logging_on)
        except Exception:
            text = self._failure(u, "fmi2Instantiate returned NULL")
            fmu.freeLibrary()
            raise CosimError(text) from None
        self._flush(u)
        f.fmu = fmu
        f.component = fmu.component
        d = fmu.dll
        for name in ("fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode",
                     "fmi2Terminate", "fmi2SetReal", "fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString",
                     "fmi2GetReal", "fmi2GetInteger", "fmi2DoStep"):
            setattr(f, name, getattr(d, name))

    def enter_initialization(self) -> None:
        when = " (start time 0 s)"
        for f in self.units:
            if f is None:
                raise CosimError("instantiate every unit first")
            self._unit(f.u)
            self._check(f, f.fmi2SetupExperiment(f.component, 0, 0.0, 0.0, 0, 0.0), "fmi2SetupExperiment", when)
            self._check(f, f.fmi2EnterInitializationMode(f.component), "fmi2EnterInitializationMode", when)

    def set(self, u: _Unit, kind: str, vrs: Sequence[int], values: Sequence) -> None:
        f = self._unit(u)
        n = len(vrs)
        vr = (c_uint * n)(*vrs)
        if kind == "Real":
            arr, fn = (c_double * n)(*values), "fmi2SetReal"
        elif kind == "Integer":
            arr, fn = (c_int * n)(*values), "fmi2SetInteger"
        elif kind == "Boolean":
            arr, fn = (c_int * n)(*values), "fmi2SetBoolean"
        else:
            arr, fn = (c_char_p * n)(*[v.encode() for v in values]), "fmi2SetString"
        self._check(f, getattr(f, fn)(f.component, vr, n, arr), fn, self._when())

    def get_reals(self, u: _Unit, vrs, out) -> None:
        """The Real variables vrs (a c_uint array) into out (a c_double array of the same length)."""
        f = self._unit(u)
        self._check(f, f.fmi2GetReal(f.component, vrs, len(vrs), out), "fmi2GetReal", self._when())

    def get(self, u: _Unit, kind: str, vr: int) -> float | int:
        f = self._unit(u)
        out = c_double() if kind == "Real" else c_int()
        fn = "fmi2GetReal" if kind == "Real" else "fmi2GetInteger"
        self._check(f, getattr(f, fn)(f.component, (c_uint * 1)(vr), 1, ctypes.byref(out)), fn, self._when())
        return out.value

    # -- the coupling, by name (as cosim.cpp's Master::resolve)
    def _resolve(self) -> None:
        c = self.coupling
        for e in c.inputs:
            if e.name not in DriveInputs.__dataclass_fields__:
                raise CosimError(f"the coupling's external input '{e.name}' is not a field of ipmsm_cosim_inputs")
            for p in e.targets:
                f = self.units[c.unit_index(p.unit)]
                f.external_vr.append(f.u.real_vr(p.variable))
                f.external_names.append(e.name)
                f.external_targets.append(p.variable)
        # One feed per (receiving, sending) unit; the sender's connected outputs laid out in
        # that order, so each feed's values are a slice of the sender's read buffer.
        self._feeds = []  # (to, from, input vrs, offset in the sender's buffer, names)
        for to, receiver in enumerate(self.units):
            for src, sender in enumerate(self.units):
                vrs, names, offset = [], [], len(sender.read_real)
                for conn in c.connections:
                    if c.unit_index(conn.target.unit) != to or c.unit_index(conn.source.unit) != src:
                        continue
                    vrs.append(receiver.u.real_vr(conn.target.variable))
                    sender.read_real.append(sender.u.real_vr(conn.source.variable))
                    names.append(conn.target.variable)
                if vrs:
                    self._feeds.append((to, src, vrs, offset, ", ".join(names)))
        for f in self.units:
            f.n_connected = len(f.read_real)
            f.real = (c_double * f.n_connected)()

    def initialize(self, start: DriveInputs) -> None:
        if any(f is None for f in self.units):
            raise CosimError("instantiate every unit first")
        if self.coupled:
            raise CosimError("initialize: already initialised")
        for f in self.units:
            self._unit(f.u)
        self._resolve()
        for i, f in enumerate(self.units):
            # its external inputs, then its connected inputs from the units before it
            vrs = list(f.external_vr)
            values = [getattr(start, name) for name in f.external_names]
            names = list(f.external_targets)
            for to, src, in_vrs, offset, feed_names in self._feeds:
                if to == i and src < i:
                    vrs += in_vrs
                    values += self.units[src].real[offset:offset + len(in_vrs)]
                    names.append(feed_names)
            if vrs:
                n = len(vrs)
                self._check(f, f.fmi2SetReal(f.component, (c_uint * n)(*vrs), n, (c_double * n)(*values)),
                            f"fmi2SetReal ({', '.join(names)})")
            self._check(f, f.fmi2ExitInitializationMode(f.component), "fmi2ExitInitializationMode")
            f.initialised = True
            if f.n_connected:
                self._check(f, f.fmi2GetReal(f.component, (c_uint * f.n_connected)(*f.read_real), f.n_connected,
                                             f.real), "fmi2GetReal")
        self._k = 0
        self.coupled = True
        self.probes([])

    def probes(self, names: Sequence[str]) -> None:
        """The read lists (connected outputs in front, keeping their values), and per probe
        where its value is in the per-step source list `reals + integers + [|i|, |i|^2]`."""
        if not self.coupled:
            raise CosimError("probes: initialise first")
        c = self.coupling
        for f in self.units:
            del f.read_real[f.n_connected:]
            f.read_int = []

        def slot(lst: list, vr: int) -> int:  # a variable read twice is read once
            if vr not in lst:
                lst.append(vr)
            return lst.index(vr)

        where = []  # per probe: ("real" | "integer", unit, slot) or (name, unit, (slot_d, slot_q))
        for name in names:
            if name in _CURRENT_PROBES:
                if "plant" not in c.roles:
                    raise CosimError(f"probe {name}: the coupling has no plant")
                p = c.unit_index("plant")
                f = self.units[p]
                where.append((name, p, (slot(f.read_real, f.u.real_vr("i_d")), slot(f.read_real, f.u.real_vr("i_q")))))
                continue
            role, _, var = name.partition(".")
            if role not in c.roles or not var:
                raise CosimError(f"probe '{name}': not ROLE.VARIABLE of a unit of the coupling, '|i|' or '|i|^2'")
            i = c.unit_index(role)
            f = self.units[i]
            if var not in f.u.vars:
                raise CosimError(f"probe '{name}': {f.u.identifier} has no variable '{var}'")
            v = f.u.vars[var]
            if v.type == "Real":
                where.append(("real", i, slot(f.read_real, v.valueReference)))
            elif v.type in ("Integer", "Enumeration"):
                where.append(("integer", i, slot(f.read_int, v.valueReference)))
            else:
                raise CosimError(f"probe '{name}' is a {v.type}: only Real and Integer variables can be averaged")
        for f in self.units:
            old = f.real[:f.n_connected]
            f.real = (c_double * len(f.read_real))(*old)
            f.integer = (c_int * len(f.read_int))()
        # The per-step source list: every unit's Reals, then every unit's Integers, then |i|, |i|^2.
        real_at, int_at, n = [], [], 0
        for f in self.units:
            real_at.append(n)
            n += len(f.read_real)
        for f in self.units:
            int_at.append(n)
            n += len(f.read_int)
        self._current = None
        index = []
        for kind, i, s in where:
            if kind == "real":
                index.append(real_at[i] + s)
            elif kind == "integer":
                index.append(int_at[i] + s)
            else:
                self._current = (real_at[i] + s[0], real_at[i] + s[1])
                index.append(n + _CURRENT_PROBES.index(kind))
        self._index = index
        self._n_probes = len(names)
        # The calls of a step with their arguments, prepared once: a feed passes the slice of the
        # sender's read buffer that holds its values.
        feeds = []
        for to, src, vrs, offset, feed_names in self._feeds:
            r, sender = self.units[to], self.units[src]
            sent = ctypes.cast(ctypes.addressof(sender.real) + offset * ctypes.sizeof(c_double), POINTER(c_double))
            feeds.append((r.fmi2SetReal, (r.component, (c_uint * len(vrs))(*vrs), len(vrs), sent), r,
                          f"fmi2SetReal ({feed_names})"))
        steps = [(f.fmi2DoStep, f.component, f) for f in self.units]
        reads = [(f.fmi2GetReal, (f.component, (c_uint * len(f.read_real))(*f.read_real), len(f.read_real), f.real), f)
                 for f in self.units]
        reads_int = [(f.fmi2GetInteger, (f.component, (c_uint * len(f.read_int))(*f.read_int), len(f.read_int),
                                         f.integer), f) for f in self.units if f.read_int]
        buffers = [f.real for f in self.units] + [f.integer for f in self.units]
        self._calls = (feeds, steps, reads, reads_int, buffers)

    def advance(self, n_steps: int, inputs: DriveInputs, trace, decimation: int):
        if not self.coupled:
            raise CosimError("advance: initialise first")
        if self.stopped:
            raise CosimError("advance: the master stopped after a failed step" + _when(self._k, self.h)
                             + "; the units are out of step: close the master")
        h, k = self.h, self._k
        when = _when(k, h)
        # The external inputs, once (refused values: k unchanged, the master stays usable).
        for f in self.units:
            if f.external_vr:
                n = len(f.external_vr)
                values = (c_double * n)(*[getattr(inputs, name) for name in f.external_names])
                self._check(f, f.fmi2SetReal(f.component, (c_uint * n)(*f.external_vr), n, values),
                            f"fmi2SetReal ({', '.join(f.external_targets)})", when)
        feeds, steps, reads, reads_int, buffers = self._calls
        pending = [f.u for f in self.units]
        index, current = self._index, self._current
        sums = [0.0] * self._n_probes
        values = sums
        sqrt = math.sqrt
        warning = int(Status.fmi2Warning)
        step_times = self._step_times
        rows = 0
        next_row = decimation if trace is not None else -1
        try:
            for step in range(1, n_steps + 1):
                t, hk = (k * h, h) if step_times is None else step_times(k)
                # The exchange: each connected input gets its output's value after the previous step.
                for set_real, args, f, what in feeds:
                    s = set_real(*args)
                    if s > warning:
                        self._fail(f, s, what, k)
                for do_step, component, f in steps:
                    s = do_step(component, t, hk, 1)
                    if s > warning:
                        self._fail(f, s, "fmi2DoStep", k)
                k += 1
                for get_real, args, f in reads:
                    s = get_real(*args)
                    if s > warning:
                        self._fail(f, s, "fmi2GetReal", k)
                for get_integer, args, f in reads_int:
                    s = get_integer(*args)
                    if s > warning:
                        self._fail(f, s, "fmi2GetInteger", k)
                for u in pending:
                    if u.pending:
                        self._flush(u)
                if index:
                    src = []
                    for b in buffers:
                        src += b[:]
                    if current is not None:
                        i_d, i_q = src[current[0]], src[current[1]]
                        sq = i_d * i_d + i_q * i_q
                        src += (sqrt(sq), sq)
                    values = [src[i] for i in index]
                    sums = [a + b for a, b in zip(sums, values)]
                if step == next_row:
                    trace[rows, 0] = k * h
                    trace[rows, 1:] = values
                    rows += 1
                    next_row += decimation
        finally:
            self._k = k
        return [x / n_steps for x in sums], [float(x) for x in values], rows

    def _fail(self, f: _FmpyUnit, status: int, function: str, k: int) -> None:
        self.stopped = True
        self._k = k
        self._check(f, status, function, _when(k, self.h))

    @property
    def k(self) -> int:
        return self._k

    def close(self) -> None:
        for f in reversed(self.units):
            if f is None or f.fmu is None:
                continue
            if f.initialised and not f.fatal:
                f.fmi2Terminate(f.component)
            f.fmu.fmi2FreeInstance(f.component)
            f.fmu.freeLibrary()
            f.fmu = None
            self._flush(f.u)


# --------------------------------------------------------------------------------------------

class DriveCosim:
    """The drive's units (IpmsmController + IpmsmPlant) coupled at h (default: the description's
    step, 100 us), advanced by the caller in chunks.

    controller_params, plant_params: {name: value} of parameters (Real, Integer, Boolean or
    String by the model description), set in Initialization Mode. T_ref, w_m, u_dc, T_magnet,
    T_winding: the external inputs at t = 0 (the controller's flying start uses them).
    advance() reports the fields of Sample (sources: SAMPLE_SOURCES). log: optional
    callable(role, status, category, message) for every message the FMUs log (also sent to the
    logging module, "scenarios.cosim.master"). step_times (fmpy only): k -> (t_k, h_k) passed to
    fmi2DoStep instead of (k h, h), to reproduce another master's clock.
    """

    def __init__(self, controller_fmu: str | Path, plant_fmu: str | Path,
                 controller_params: Mapping | None = None, plant_params: Mapping | None = None,
                 h: float | None = None, backend: str = "native",
                 w_m: float = 0.0, u_dc: float = 355.0, T_magnet: float = 293.15, T_winding: float = 293.15,
                 T_ref: float = 0.0, logging_on: bool = False, log: Callable | None = None,
                 library: str | Path | None = None, instance_prefix: str = "", coupling: Coupling = DRIVE,
                 step_times: Callable[[int], tuple[float, float]] | None = None):
        h = coupling.step if h is None else h
        if not (isinstance(h, (int, float)) and math.isfinite(h) and h > 0):
            raise ValueError(f"h = {h!r}: must be a finite number > 0")
        if backend == "auto":
            backend = "native" if default_library(controller_fmu if library is None else None).exists() or \
                (library is not None and Path(library).exists()) else "fmpy"
        if backend not in ("native", "fmpy"):
            raise ValueError(f"backend = {backend!r}: 'native', 'fmpy' or 'auto'")
        if step_times is not None and backend != "fmpy":
            raise ValueError("step_times: only with backend='fmpy'")
        self.backend_name = backend
        self.h = float(h)
        self.coupling = coupling
        self.messages: deque = deque(maxlen=200)  # (role, status, category, message), the latest
        self._user_log = log
        self._units: dict[str, _Unit] = {}
        self._b = None
        self._closed = False
        try:
            paths = {"controller": controller_fmu, "plant": plant_fmu}
            params = {"controller": controller_params or {}, "plant": plant_params or {}}
            if set(paths) != set(coupling.roles):
                raise CosimError(f"the coupling's units are {coupling.roles}: DriveCosim couples a controller "
                                 "and a plant")
            for unit in coupling.units:
                self._units[unit.role] = _Unit(unit.role, unit.model_identifier, paths[unit.role],
                                               instance_prefix + unit.role)
            if backend == "native":
                self._b = _NativeBackend(Path(library) if library else default_library(controller_fmu), coupling,
                                         self.h, self._log)
            else:
                self._b = _FmpyBackend(coupling, self.h, self._log, step_times)
            b = self._b
            for u in self._units.values():
                b.instantiate(u, logging_on)
            b.enter_initialization()
            for role, u in self._units.items():
                self._set_parameters(u, params[role])
            self._inputs = DriveInputs(float(T_ref), float(w_m), float(u_dc), float(T_magnet), float(T_winding))
            b.initialize(self._inputs)
            b.probes([SAMPLE_SOURCES[name] for name in SAMPLE_FIELDS])
            # the plant's integrals, read after every advance: their value references resolved once
            vrs = [self._units["plant"].variable(name).valueReference for name in PLANT_INTEGRALS]
            self._integral_vrs, self._integral_values = (c_uint * len(vrs))(*vrs), (c_double * len(vrs))()
            self._integrals = self._plant_integrals()
        except BaseException:
            self.close()
            raise

    # -- set-up helpers
    def _set_parameters(self, u: _Unit, params: Mapping) -> None:
        groups: dict[str, tuple[list, list]] = {}
        for name, value in params.items():
            v = u.variable(name)
            if v.causality not in ("parameter", "input"):
                raise CosimError(f"{u.identifier}.{name} is {v.causality}, not a parameter")
            if v.type == "Real":
                value = float(value)
            elif v.type in ("Integer", "Enumeration"):
                value = int(value)
            elif v.type == "Boolean":
                value = int(bool(value))
            else:
                value = str(value)
            kind = "Integer" if v.type == "Enumeration" else v.type
            vrs, values = groups.setdefault(kind, ([], []))
            vrs.append(v.valueReference)
            values.append(value)
        for kind in ("Real", "Integer", "Boolean", "String"):
            if kind in groups:
                self._b.set(u, kind, *groups[kind])

    def _log(self, role: str, status: int, category: str, message: str) -> None:
        u = self._units.get(role)
        self.messages.append((role, status, category, message))
        level = {Status.fmi2OK: logging.INFO, Status.fmi2Warning: logging.WARNING}.get(status, logging.ERROR)
        LOG.log(level, "[%s %s] %s", u.instance_name if u else role, category, message)
        if self._user_log is not None:
            self._user_log(role, status, category, message)

    # -- the API
    @property
    def k(self) -> int:
        """Index of the next step: the master is at t = k h."""
        return self._b.k

    @property
    def t(self) -> float:
        return self._b.k * self.h

    @property
    def trace_columns(self) -> tuple[str, ...]:
        return ("t",) + SAMPLE_FIELDS

    def value(self, name: str) -> float | int:
        """The current value of "ROLE.VARIABLE" (a Real or Integer variable)."""
        role, _, var = name.partition(".")
        if role not in self._units:
            raise CosimError(f"{name!r}: no unit '{role}' (units: {', '.join(self._units)})")
        u = self._units[role]
        v = u.variable(var)
        if v.type not in ("Real", "Integer", "Enumeration"):
            raise CosimError(f"{name!r} is a {v.type}: only Real and Integer variables are read")
        return self._b.get(u, "Real" if v.type == "Real" else "Integer", v.valueReference)

    def advance(self, n_steps: int, T_ref: float, w_m: float, u_dc: float | None = None,
                T_magnet: float | None = None, T_winding: float | None = None,
                trace: np.ndarray | None = None, decimation: int = 1) -> AdvanceResult:
        """n_steps coupled steps of h with T_ref, w_m, u_dc, T_magnet, T_winding held (None: as in
        the previous call, or as at construction). Returns an AdvanceResult (means and end
        values as Samples). trace: a C-contiguous float64 array of at least n_steps // decimation
        rows and len(trace_columns) columns; row r gets t and the Sample after step
        (r + 1) * decimation."""
        if self._closed:
            raise CosimError("advance: the master is closed")
        if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 1:
            raise ValueError(f"n_steps = {n_steps!r}: must be an integer >= 1")
        held = self._inputs
        new = DriveInputs(float(T_ref), float(w_m), held.u_dc if u_dc is None else float(u_dc),
                          held.T_magnet if T_magnet is None else float(T_magnet),
                          held.T_winding if T_winding is None else float(T_winding))
        if trace is not None:
            decimation = int(decimation)
            if decimation < 1:
                raise ValueError(f"decimation = {decimation}: must be >= 1")
            if not (isinstance(trace, np.ndarray) and trace.dtype == np.float64 and trace.ndim == 2
                    and trace.flags.c_contiguous and trace.flags.writeable
                    and trace.shape[1] == len(self.trace_columns)):
                raise ValueError(f"trace: a writeable C-contiguous float64 array of shape (>= {n_steps // decimation}, "
                                 f"{len(self.trace_columns)}) is needed")
            if trace.shape[0] < n_steps // decimation:
                raise ValueError(f"trace has {trace.shape[0]} rows, {n_steps // decimation} are needed")
        mean, end, rows = self._b.advance(int(n_steps), new, trace, decimation)
        self._inputs = new
        m = Sample(*mean)
        self._exact_means(m, n_steps * self.h, new.w_m)
        return AdvanceResult(mean=m, end=Sample(*end), t=self._b.k * self.h, k=self._b.k, rows=rows)

    def _plant_integrals(self) -> list[float]:
        self._b.get_reals(self._units["plant"], self._integral_vrs, self._integral_values)
        return self._integral_values[:]

    def _exact_means(self, m: Sample, duration: float, w_m: float) -> None:
        """The powers' and torques' means over the advance from the plant's exact integrals
        (PLANT_INTEGRALS), as IpmsmDrive reports them; the currents stay the samples' means."""
        now = self._plant_integrals()
        E_elec, E_mech, E_cu, E_fe, impulse = ((b - a) / duration for a, b in zip(self._integrals, now))
        self._integrals = now
        m.P_elec, m.P_mech, m.P_cu, m.P_fe, m.T_e = E_elec, E_mech, E_cu, E_fe, impulse
        m.T_shaft = impulse - E_fe / w_m if w_m != 0.0 else impulse  # the iron-loss drag at the held speed

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            if self._b is not None:
                self._b.close()
        finally:
            for u in self._units.values():
                u.remove_dir()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
