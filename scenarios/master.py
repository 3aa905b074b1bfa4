"""The co-simulation master for drive cycles: IpmsmController + IpmsmPlant, Jacobi-coupled at a
fixed communication step h (default 100 us), driven by a slower caller (the vehicle side) that
holds the slow inputs over each call of `advance`.

    from scenarios.master import DriveCosim
    with DriveCosim("build/fmu/IpmsmController.fmu", "build/fmu/IpmsmPlant.fmu", w_m=100.0) as cosim:
        r = cosim.advance(100, T_ref=120.0, w_m=100.0, u_dc=355.0, T_magnet=353.15, T_winding=373.15)
        r.mean.T_shaft, r.end.i_q, r.t, r.k      # an AdvanceResult; mean and end are Samples

One interface, two backends that make the same FMI calls in the same order (so their results
are bit-identical, tests/python/test_master.py checks it):
- "native": build/lib/libipmsm_cosim.so (scenarios/native/cosim.cpp) via ctypes; the 100 us
  loop runs in C++. For drive cycles.
- "fmpy": the same loop in Python on the FMUs' functions as loaded by fmpy's FMU2Slave (ctypes
  arguments converted once). The reference, and the fallback when the library is not built.
- "auto": native if the library exists, else fmpy.

Each coupled step k (t_k = k h, k an integer: time is never an accumulated sum):
    plant.u_d, u_q      <- controller.u_d_ref, u_q_ref of the previous step (after
                           initialisation: the controller's flying-start voltage)
    controller.i_d, i_q <- plant.i_d, i_q at t_k
    plant.doStep(t_k, h); controller.doStep(t_k, h)
    read the outputs at t_{k+1}: the coupling values, and the probes (`outputs`)
`advance` sets the slow inputs once before its steps (controller: T_ref, w_m, u_dc, T_magnet;
plant: w_m, T_magnet, T_winding) and returns, per output, the mean over its steps of the value
after each step and the value after the last step.

Initialisation: both instantiated (controller, then plant); the plant initialised first
(parameters, then w_m, T_magnet, T_winding), then the controller with the plant's initial
current as its measured current and w_m, u_dc, T_magnet, T_ref set before
fmi2ExitInitializationMode (its flying start needs them).

Errors: any FMI call returning fmi2Error/fmi2Fatal raises CosimError naming the FMU, the
function, the time and step, with the FMU's log message. A refused slow input (NaN, u_dc <= 0,
out of range) changes nothing: fix it and call again. A failure while stepping stops the master
(the two FMUs are then out of step): close it.
"""
from __future__ import annotations

import ctypes
import logging
import math
import os
import shutil
from collections import deque
from dataclasses import dataclass, fields
from ctypes import POINTER, c_char_p, c_double, c_int, c_longlong, c_size_t, c_uint, c_void_p
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
from fmpy import extract, read_model_description

ROOT = Path(__file__).resolve().parents[1]
LOG = logging.getLogger("scenarios.master")

CONTROLLER, PLANT = 0, 1
_LABEL = ("controller", "plant")
REAL, INTEGER, CURRENT_ABS, CURRENT_SQ = 0, 1, 2, 3  # probe kinds, as in cosim.h
_STATUS = ("fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal", "fmi2Pending")



@dataclass(frozen=True)
class Sample:
    """The drive's outputs at one instant, or their means over the steps of one `advance`.
    SI units, named as in the contract (INTERFACE.md): the plant's T_shaft, T_e, P_elec, P_mech,
    P_cu, P_fe, i_d, i_q; i_abs = sqrt(i_d^2 + i_q^2) and i_abs_sq = i_d^2 + i_q^2 of the plant's
    currents (the mean of i_abs_sq is what the inverter's conduction loss needs); the
    controller's T_cmd, T_max, region, iterations, u_ratio (Integers as floats: a mean of region
    is the time share weighted region, rarely useful)."""
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


@dataclass(frozen=True)
class AdvanceResult:
    """What one `DriveCosim.advance` returns: per output, the mean over its steps of the value
    after each step, and the value after the last step; the time t = k h and step index k
    after it; the number of trace rows written."""
    mean: Sample
    end: Sample
    t: float
    k: int
    rows: int


# Where each field of Sample comes from: "controller.X" / "plant.X" a variable of that FMU;
# "|i|" and "|i|^2" of the plant's currents (computed by the master).
SAMPLE_SOURCES = {
    "T_shaft": "plant.T_shaft", "T_e": "plant.T_e", "P_elec": "plant.P_elec", "P_mech": "plant.P_mech",
    "P_cu": "plant.P_cu", "P_fe": "plant.P_fe", "i_d": "plant.i_d", "i_q": "plant.i_q", "i_abs": "|i|",
    "i_abs_sq": "|i|^2", "T_cmd": "controller.T_cmd", "T_max": "controller.T_max", "region": "controller.region",
    "iterations": "controller.iterations", "u_ratio": "controller.u_ratio",
}
SAMPLE_FIELDS = tuple(f.name for f in fields(Sample))

# The coupling variables (FMI names): controller inputs T_ref, w_m, u_dc, T_magnet, i_d, i_q and
# outputs u_d_ref, u_q_ref; plant inputs u_d, u_q, w_m, T_magnet, T_winding and outputs i_d, i_q.
_C_COUPLING = ("T_ref", "w_m", "u_dc", "T_magnet", "i_d", "i_q", "u_d_ref", "u_q_ref")
_P_COUPLING = ("u_d", "u_q", "w_m", "T_magnet", "T_winding", "i_d", "i_q")


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
    return " at t = %.9g s (step k = %d)" % (k * h, k)


class _Unit:
    """What both backends know of one FMU: its model description and extracted folder."""

    def __init__(self, index: int, path: str | Path, instance_name: str):
        self.index = index
        self.path = Path(path)
        self.md = read_model_description(str(self.path))
        self.identifier = self.md.coSimulation.modelIdentifier
        self.instance_name = instance_name
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.dir = extract(str(self.path))
        self.pending: list[tuple[int, str, str]] = []  # (status, category, message) of the current call

    def variable(self, name: str):
        try:
            return self.vars[name]
        except KeyError:
            raise CosimError(f"{self.identifier} has no variable {name!r}") from None

    def describe(self) -> str:
        return f"{self.identifier} ({_LABEL[self.index]}, instance '{self.instance_name}')"

    def remove_dir(self) -> None:
        if self.dir:
            shutil.rmtree(self.dir, ignore_errors=True)
            self.dir = None


# --------------------------------------------------------------------------------------------
# Backends: the same primitive operations; DriveCosim calls them in the same order for both.

class _NativeBackend:
    _LOG_FN = ctypes.CFUNCTYPE(None, c_void_p, c_int, c_char_p, c_int, c_char_p, c_char_p)
    _libs: dict[str, ctypes.CDLL] = {}

    def __init__(self, library: Path, h: float, log: Callable):
        self.lib = self._load(Path(library))
        self._log_cb = self._LOG_FN(lambda user, unit, inst, status, cat, msg:
                                    log(unit, status, (cat or b"").decode(errors="replace"),
                                        (msg or b"").decode(errors="replace")))
        self.m = self.lib.ipmsm_cosim_new(h, self._log_cb, None)
        if not self.m:
            raise CosimError(f"ipmsm_cosim_new refused h = {h!r}")
        self.h = h

    @classmethod
    def _load(cls, library: Path) -> ctypes.CDLL:
        key = str(library.resolve()) if library.exists() else str(library)
        if key in cls._libs:
            return cls._libs[key]
        if not library.exists():
            raise FileNotFoundError(f"{library} is missing: build it (cmake --build build) or use backend='fmpy'")
        lib = ctypes.CDLL(key)
        P = c_void_p
        u_p, d_p, i_p = POINTER(c_uint), POINTER(c_double), POINTER(c_int)
        sig = {
            "ipmsm_cosim_new": (P, [c_double, cls._LOG_FN, P]),
            "ipmsm_cosim_free": (None, [P]),
            "ipmsm_cosim_error": (c_char_p, [P]),
            "ipmsm_cosim_instantiate": (c_int, [P, c_int, c_char_p, c_char_p, c_char_p, c_char_p, c_int]),
            "ipmsm_cosim_enter_initialization": (c_int, [P, c_int, c_double]),
            "ipmsm_cosim_exit_initialization": (c_int, [P, c_int]),
            "ipmsm_cosim_set_real": (c_int, [P, c_int, c_size_t, u_p, d_p]),
            "ipmsm_cosim_set_integer": (c_int, [P, c_int, c_size_t, u_p, i_p]),
            "ipmsm_cosim_set_boolean": (c_int, [P, c_int, c_size_t, u_p, i_p]),
            "ipmsm_cosim_set_string": (c_int, [P, c_int, c_size_t, u_p, POINTER(c_char_p)]),
            "ipmsm_cosim_get_real": (c_int, [P, c_int, c_size_t, u_p, d_p]),
            "ipmsm_cosim_get_integer": (c_int, [P, c_int, c_size_t, u_p, i_p]),
            "ipmsm_cosim_couple": (c_int, [P, u_p, u_p, c_longlong]),
            "ipmsm_cosim_probes": (c_int, [P, c_size_t, i_p, i_p, u_p]),
            "ipmsm_cosim_advance": (c_longlong, [P, c_longlong, d_p, d_p, d_p, P, c_longlong, c_longlong]),
            "ipmsm_cosim_step_index": (c_longlong, [P]),
            "ipmsm_cosim_time": (c_double, [P]),
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
        self._check(self.lib.ipmsm_cosim_instantiate(self.m, u.index, str(u.dir).encode(), u.identifier.encode(),
                                                     u.md.guid.encode(), u.instance_name.encode(), int(logging_on)))

    def enter_initialization(self, u: _Unit, start_time: float) -> None:
        self._check(self.lib.ipmsm_cosim_enter_initialization(self.m, u.index, start_time))

    def exit_initialization(self, u: _Unit) -> None:
        self._check(self.lib.ipmsm_cosim_exit_initialization(self.m, u.index))

    def set(self, u: _Unit, kind: str, vrs: Sequence[int], values: Sequence) -> None:
        n = len(vrs)
        vr = (c_uint * n)(*vrs)
        if kind == "Real":
            self._check(self.lib.ipmsm_cosim_set_real(self.m, u.index, n, vr, (c_double * n)(*values)))
        elif kind == "Integer":
            self._check(self.lib.ipmsm_cosim_set_integer(self.m, u.index, n, vr, (c_int * n)(*values)))
        elif kind == "Boolean":
            self._check(self.lib.ipmsm_cosim_set_boolean(self.m, u.index, n, vr, (c_int * n)(*values)))
        else:
            self._check(self.lib.ipmsm_cosim_set_string(self.m, u.index, n, vr,
                                                        (c_char_p * n)(*[v.encode() for v in values])))

    def get_real(self, u: _Unit, vrs: Sequence[int]) -> list[float]:
        n = len(vrs)
        out = (c_double * n)()
        self._check(self.lib.ipmsm_cosim_get_real(self.m, u.index, n, (c_uint * n)(*vrs), out))
        return list(out)

    def get_integer(self, u: _Unit, vrs: Sequence[int]) -> list[int]:
        n = len(vrs)
        out = (c_int * n)()
        self._check(self.lib.ipmsm_cosim_get_integer(self.m, u.index, n, (c_uint * n)(*vrs), out))
        return list(out)

    def couple(self, c_vr: Sequence[int], p_vr: Sequence[int]) -> None:
        self._check(self.lib.ipmsm_cosim_couple(self.m, (c_uint * 8)(*c_vr), (c_uint * 7)(*p_vr), 0))

    def probes(self, probes: Sequence[tuple[int, int, int]]) -> None:
        n = len(probes)
        self.n_probes = n
        self._check(self.lib.ipmsm_cosim_probes(self.m, n, (c_int * n)(*[p[0] for p in probes]),
                                                (c_int * n)(*[p[1] for p in probes]),
                                                (c_uint * n)(*[p[2] for p in probes])))
        self._slow = (c_double * 5)()
        self._mean = (c_double * max(n, 1))()
        self._end = (c_double * max(n, 1))()
        self._advance = self.lib.ipmsm_cosim_advance

    def advance(self, n_steps: int, slow: Sequence[float], trace, decimation: int):
        s = self._slow
        s[0], s[1], s[2], s[3], s[4] = slow
        if trace is None:
            rows = self._advance(self.m, n_steps, s, self._mean, self._end, None, 0, 0)
        else:
            rows = self._advance(self.m, n_steps, s, self._mean, self._end, trace.ctypes.data, trace.shape[0],
                                 decimation)
        if rows < 0:
            raise CosimError(self.lib.ipmsm_cosim_error(self.m).decode(errors="replace"))
        n = self.n_probes
        return self._mean[:n], self._end[:n], rows

    @property
    def k(self) -> int:
        return self.lib.ipmsm_cosim_step_index(self.m)

    def close(self) -> None:
        if self.m:
            self.lib.ipmsm_cosim_free(self.m)
            self.m = None


class _FmpyBackend:
    """The same master in Python, on the FMUs' C functions as fmpy's FMU2Slave loads them."""

    def __init__(self, h: float, log: Callable):
        from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, defaultCallbacks
        self.h = h
        self._log = log
        self.fmus: dict[int, object] = {}
        self.units: dict[int, _Unit] = {}
        self.initialised = {CONTROLLER: False, PLANT: False}
        self.fatal = {CONTROLLER: False, PLANT: False}
        self.stopped = False
        self.coupled = False
        self._k = 0

        def logger(env, instance, status, category, message):
            u = self.units.get((env or 0) - 1)
            if u is not None and len(u.pending) < 1000:
                # the FMU doubles '%' for printf-style loggers: undo it as printf would
                text = (message or b"").decode(errors="replace").replace("%%", "%")
                u.pending.append((status, (category or b"").decode(errors="replace"), text))

        self._callbacks = {}
        for unit in (CONTROLLER, PLANT):
            cb = fmi2CallbackFunctions()
            cb.logger = fmi2CallbackLoggerTYPE(logger)
            cb.allocateMemory = defaultCallbacks.allocateMemory
            cb.freeMemory = defaultCallbacks.freeMemory
            cb.componentEnvironment = unit + 1
            self._callbacks[unit] = cb

    # -- the status check, as the native master's
    def _flush(self, u: _Unit, quoted: bool = False) -> None:
        for status, category, message in u.pending:
            if not (quoted and status >= 1):
                self._log(u.index, status, category, message)
        u.pending.clear()

    def _check(self, u: _Unit, status: int, function: str, when: str = "") -> None:
        if status <= 1:
            if u.pending:
                self._flush(u)
            return
        if status == 4:
            self.fatal[u.index] = True
        messages = [m for s, _, m in u.pending if s >= 1]
        name = _STATUS[status] if 0 <= status < len(_STATUS) else "an unknown fmi2Status"
        text = f"{u.describe()}: {function}{when} returned {name}"
        text += (": " + "; ".join(messages)) if messages else " (the FMU logged no message)"
        self._flush(u, quoted=True)
        raise CosimError(text)

    def _usable(self, u: _Unit) -> None:
        if self.fatal[u.index]:
            raise CosimError(f"{u.identifier} reported fmi2Fatal earlier: it can only be freed")

    def instantiate(self, u: _Unit, logging_on: bool) -> None:
        from fmpy.fmi2 import FMU2Slave
        self.units[u.index] = u
        fmu = FMU2Slave(guid=u.md.guid, unzipDirectory=u.dir, modelIdentifier=u.identifier,
                        instanceName=u.instance_name)
        try:
            fmu.instantiate(callbacks=self._callbacks[u.index], loggingOn=logging_on)
        except Exception:
            messages = [m for s, _, m in u.pending if s >= 1]
            self._flush(u, quoted=True)
            fmu.freeLibrary()
            raise CosimError(f"{u.describe()}: fmi2Instantiate returned NULL"
                             + (": " + "; ".join(messages) if messages else "")) from None
        self._flush(u)
        self.fmus[u.index] = fmu
        d = fmu.dll
        fmu.raw = {name: getattr(d, name) for name in
                   ("fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode",
                    "fmi2Terminate", "fmi2SetReal", "fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString",
                    "fmi2GetReal", "fmi2GetInteger", "fmi2DoStep")}

    def enter_initialization(self, u: _Unit, start_time: float) -> None:
        self._usable(u)
        fmu = self.fmus[u.index]
        when = " (start time %.9g s)" % start_time
        self._check(u, fmu.raw["fmi2SetupExperiment"](fmu.component, 0, 0.0, start_time, 0, 0.0),
                    "fmi2SetupExperiment", when)
        self._check(u, fmu.raw["fmi2EnterInitializationMode"](fmu.component), "fmi2EnterInitializationMode", when)

    def exit_initialization(self, u: _Unit) -> None:
        self._usable(u)
        fmu = self.fmus[u.index]
        self._check(u, fmu.raw["fmi2ExitInitializationMode"](fmu.component), "fmi2ExitInitializationMode")
        self.initialised[u.index] = True

    def _when(self) -> str:
        return _when(self._k, self.h) if self.coupled else ""

    def set(self, u: _Unit, kind: str, vrs: Sequence[int], values: Sequence) -> None:
        self._usable(u)
        fmu = self.fmus[u.index]
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
        self._check(u, fmu.raw[fn](fmu.component, vr, n, arr), fn, self._when())

    def get_real(self, u: _Unit, vrs: Sequence[int]) -> list[float]:
        self._usable(u)
        fmu = self.fmus[u.index]
        n = len(vrs)
        out = (c_double * n)()
        self._check(u, fmu.raw["fmi2GetReal"](fmu.component, (c_uint * n)(*vrs), n, out), "fmi2GetReal", self._when())
        return list(out)

    def get_integer(self, u: _Unit, vrs: Sequence[int]) -> list[int]:
        self._usable(u)
        fmu = self.fmus[u.index]
        n = len(vrs)
        out = (c_int * n)()
        self._check(u, fmu.raw["fmi2GetInteger"](fmu.component, (c_uint * n)(*vrs), n, out), "fmi2GetInteger",
                    self._when())
        return list(out)

    def couple(self, c_vr: Sequence[int], p_vr: Sequence[int]) -> None:
        if not (self.initialised[CONTROLLER] and self.initialised[PLANT]):
            raise CosimError("couple: initialise both units first")
        self._c_slow = (c_uint * 4)(*c_vr[:4])
        self._c_in_i = (c_uint * 2)(*c_vr[4:6])
        self._p_in_u = (c_uint * 2)(*p_vr[:2])
        self._p_slow = (c_uint * 3)(*p_vr[2:5])
        self._c_out = list(c_vr[6:8])
        self._p_out = list(p_vr[5:7])
        self._k = 0
        self.coupled = True
        self.stopped = False
        self._probes([])
        c, p = self.units[CONTROLLER], self.units[PLANT]
        cf, pf = self.fmus[CONTROLLER], self.fmus[PLANT]
        when = _when(self._k, self.h)
        self._check(p, pf.raw["fmi2GetReal"](pf.component, self._p_rvr, 2, self._p_real), "fmi2GetReal", when)
        self._check(c, cf.raw["fmi2GetReal"](cf.component, self._c_rvr, 2, self._c_real), "fmi2GetReal", when)

    def _probes(self, probes: Sequence[tuple[int, int, int]]) -> None:
        # The read lists, as the native master builds them: Reals with the coupling outputs in
        # front, then each new probe vr; Integers.
        real = {CONTROLLER: list(self._c_out), PLANT: list(self._p_out)}
        ints = {CONTROLLER: [], PLANT: []}
        slots = []  # per probe: index into the per-step source list (see advance)
        for unit, kind, vr in probes:
            if kind in (REAL, INTEGER):
                lst = real[unit] if kind == REAL else ints[unit]
                if vr not in lst:
                    lst.append(vr)
                slots.append((unit, kind, lst.index(vr)))
            else:
                slots.append((PLANT, kind, 0))
        old = (list(self._c_real[:2]), list(self._p_real[:2])) if hasattr(self, "_c_real") else None
        self._c_rvr = (c_uint * len(real[CONTROLLER]))(*real[CONTROLLER])
        self._p_rvr = (c_uint * len(real[PLANT]))(*real[PLANT])
        self._c_ivr = (c_uint * len(ints[CONTROLLER]))(*ints[CONTROLLER])
        self._p_ivr = (c_uint * len(ints[PLANT]))(*ints[PLANT])
        self._c_real = (c_double * len(real[CONTROLLER]))()
        self._p_real = (c_double * len(real[PLANT]))()
        self._c_int = (c_int * max(1, len(ints[CONTROLLER])))()
        self._p_int = (c_int * max(1, len(ints[PLANT])))()
        if old is not None:
            self._c_real[0], self._c_real[1] = old[0]
            self._p_real[0], self._p_real[1] = old[1]
        # The per-step source list is  p_real + c_real + p_int + c_int + [|i|, |i|^2]
        n_pr, n_cr = len(real[PLANT]), len(real[CONTROLLER])
        n_pi, n_ci = len(ints[PLANT]), len(ints[CONTROLLER])
        index = []
        for unit, kind, slot in slots:
            if kind == REAL:
                index.append(slot if unit == PLANT else n_pr + slot)
            elif kind == INTEGER:
                index.append(n_pr + n_cr + (slot if unit == PLANT else n_pi + slot))
            else:
                index.append(n_pr + n_cr + n_pi + n_ci + (0 if kind == CURRENT_ABS else 1))
        self._index = index
        self.n_probes = len(probes)

    def probes(self, probes: Sequence[tuple[int, int, int]]) -> None:
        if not self.coupled:
            raise CosimError("probes: couple first")
        self._probes(probes)

    def advance(self, n_steps: int, slow: Sequence[float], trace, decimation: int):
        if not self.coupled:
            raise CosimError("advance: couple first")
        if self.stopped:
            raise CosimError("advance: the master stopped after a failed step" + _when(self._k, self.h)
                             + "; the units are out of step: close the master")
        c, p = self.units[CONTROLLER], self.units[PLANT]
        cf, pf = self.fmus[CONTROLLER], self.fmus[PLANT]
        cc, pc = cf.component, pf.component
        h = self.h
        T_ref, w_m, u_dc, T_magnet, T_winding = slow
        when = _when(self._k, h)
        self._check(c, cf.raw["fmi2SetReal"](cc, self._c_slow, 4, (c_double * 4)(T_ref, w_m, u_dc, T_magnet)),
                    "fmi2SetReal (T_ref, w_m, u_dc, T_magnet)", when)
        self._check(p, pf.raw["fmi2SetReal"](pc, self._p_slow, 3, (c_double * 3)(w_m, T_magnet, T_winding)),
                    "fmi2SetReal (w_m, T_magnet, T_winding)", when)
        c_set, p_set = cf.raw["fmi2SetReal"], pf.raw["fmi2SetReal"]
        c_step, p_step = cf.raw["fmi2DoStep"], pf.raw["fmi2DoStep"]
        c_get, p_get = cf.raw["fmi2GetReal"], pf.raw["fmi2GetReal"]
        c_geti, p_geti = cf.raw["fmi2GetInteger"], pf.raw["fmi2GetInteger"]
        c_real, p_real, c_int_, p_int_ = self._c_real, self._p_real, self._c_int, self._p_int
        c_rvr, p_rvr, c_ivr, p_ivr = self._c_rvr, self._p_rvr, self._c_ivr, self._p_ivr
        c_nr, p_nr, c_ni, p_ni = len(c_rvr), len(p_rvr), len(c_ivr), len(p_ivr)
        c_in_i, p_in_u = self._c_in_i, self._p_in_u
        index = self._index
        n_probes = len(index)
        sums = [0.0] * n_probes
        values = sums
        sqrt = math.sqrt
        rows = 0
        next_row = decimation if trace is not None else -1
        k = self._k
        try:
            for step in range(1, n_steps + 1):
                t = k * h
                s = p_set(pc, p_in_u, 2, c_real)
                if s > 1:
                    self._fail(p, s, "fmi2SetReal (u_d, u_q)", k)
                s = c_set(cc, c_in_i, 2, p_real)
                if s > 1:
                    self._fail(c, s, "fmi2SetReal (i_d, i_q)", k)
                s = p_step(pc, t, h, 1)
                if s > 1:
                    self._fail(p, s, "fmi2DoStep", k)
                s = c_step(cc, t, h, 1)
                if s > 1:
                    self._fail(c, s, "fmi2DoStep", k)
                k += 1
                s = p_get(pc, p_rvr, p_nr, p_real)
                if s > 1:
                    self._fail(p, s, "fmi2GetReal", k)
                s = c_get(cc, c_rvr, c_nr, c_real)
                if s > 1:
                    self._fail(c, s, "fmi2GetReal", k)
                if p_ni:
                    s = p_geti(pc, p_ivr, p_ni, p_int_)
                    if s > 1:
                        self._fail(p, s, "fmi2GetInteger", k)
                if c_ni:
                    s = c_geti(cc, c_ivr, c_ni, c_int_)
                    if s > 1:
                        self._fail(c, s, "fmi2GetInteger", k)
                if p.pending:
                    self._flush(p)
                if c.pending:
                    self._flush(c)
                if n_probes:
                    pr = p_real[:]
                    i_d, i_q = pr[0], pr[1]
                    sq = i_d * i_d + i_q * i_q
                    src = pr + c_real[:] + [float(x) for x in p_int_[:p_ni]] + [float(x) for x in c_int_[:c_ni]] \
                        + [sqrt(sq), sq]
                    values = [src[i] for i in index]
                    sums = [a + b for a, b in zip(sums, values)]
                    if step == next_row:
                        trace[rows, 0] = k * h
                        trace[rows, 1:] = values
                        rows += 1
                        next_row += decimation
                elif step == next_row:
                    trace[rows, 0] = k * h
                    rows += 1
                    next_row += decimation
        finally:
            self._k = k
        return [x / n_steps for x in sums], list(values), rows

    def _fail(self, u: _Unit, status: int, function: str, k: int) -> None:
        self.stopped = True
        self._k = k
        self._check(u, status, function, _when(k, self.h))

    @property
    def k(self) -> int:
        return self._k

    def close(self) -> None:
        for index in (PLANT, CONTROLLER):
            fmu = self.fmus.pop(index, None)
            if fmu is None:
                continue
            u = self.units[index]
            if self.initialised[index] and not self.fatal[index]:
                fmu.raw["fmi2Terminate"](fmu.component)
            fmu.fmi2FreeInstance(fmu.component)
            fmu.freeLibrary()
            self._flush(u)


# --------------------------------------------------------------------------------------------

class DriveCosim:
    """IpmsmController + IpmsmPlant at h (default 100 us), advanced by the caller in chunks.

    controller_params, plant_params: {name: value} of parameters (Real, Integer, Boolean or
    String by the model description), set in initialisation mode. w_m, u_dc, T_magnet, T_winding,
    T_ref: the inputs at t = 0 (the controller's flying start uses them). advance() reports the
    fields of Sample (sources: SAMPLE_SOURCES). log: optional callable(unit_name, status, category, message)
    for every message the FMUs log (also sent to the logging module, "scenarios.master").
    """

    def __init__(self, controller_fmu: str | Path, plant_fmu: str | Path,
                 controller_params: Mapping | None = None, plant_params: Mapping | None = None,
                 h: float = 1e-4, backend: str = "native",
                 w_m: float = 0.0, u_dc: float = 355.0, T_magnet: float = 293.15, T_winding: float = 293.15,
                 T_ref: float = 0.0, logging_on: bool = False, log: Callable | None = None,
                 library: str | Path | None = None, instance_prefix: str = ""):
        if not (isinstance(h, (int, float)) and math.isfinite(h) and h > 0):
            raise ValueError(f"h = {h!r}: must be a finite number > 0")
        if backend == "auto":
            backend = "native" if default_library(controller_fmu if library is None else None).exists() or \
                (library is not None and Path(library).exists()) else "fmpy"
        if backend not in ("native", "fmpy"):
            raise ValueError(f"backend = {backend!r}: 'native', 'fmpy' or 'auto'")
        self.backend_name = backend
        self.h = float(h)
        self.messages: deque = deque(maxlen=200)  # (unit, status, category, message), the latest
        self._user_log = log
        self._units: list[_Unit] = []
        self._b = None
        self._closed = False
        try:
            self._units = [_Unit(CONTROLLER, controller_fmu, instance_prefix + "controller"),
                           _Unit(PLANT, plant_fmu, instance_prefix + "plant")]
            c, p = self._units
            if backend == "native":
                self._b = _NativeBackend(Path(library) if library else default_library(controller_fmu), self.h,
                                         self._log)
            else:
                self._b = _FmpyBackend(self.h, self._log)
            self._probes = [self._probe(SAMPLE_SOURCES[name]) for name in SAMPLE_FIELDS]
            b = self._b
            b.instantiate(c, logging_on)
            b.instantiate(p, logging_on)
            # the plant first: the controller's flying start needs the plant's initial current
            b.enter_initialization(p, 0.0)
            self._set_parameters(p, plant_params or {})
            b.set(p, "Real", [p.variable(n).valueReference for n in ("w_m", "T_magnet", "T_winding")],
                  [float(w_m), float(T_magnet), float(T_winding)])
            b.exit_initialization(p)
            i_d, i_q = b.get_real(p, [p.variable("i_d").valueReference, p.variable("i_q").valueReference])
            b.enter_initialization(c, 0.0)
            self._set_parameters(c, controller_params or {})
            b.set(c, "Real", [c.variable(n).valueReference for n in ("T_ref", "w_m", "u_dc", "T_magnet", "i_d", "i_q")],
                  [float(T_ref), float(w_m), float(u_dc), float(T_magnet), i_d, i_q])
            b.exit_initialization(c)
            b.couple([c.variable(n).valueReference for n in _C_COUPLING],
                     [p.variable(n).valueReference for n in _P_COUPLING])
            b.probes([(u, kind, vr) for (u, kind, vr) in self._probes])
            self._slow = [float(T_ref), float(w_m), float(u_dc), float(T_magnet), float(T_winding)]
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

    def _probe(self, name: str) -> tuple[int, int, int]:
        c, p = self._units
        if name in ("|i|", "plant.|i|"):
            return (PLANT, CURRENT_ABS, 0)
        if name in ("|i|^2", "plant.|i|^2"):
            return (PLANT, CURRENT_SQ, 0)
        if name.startswith("controller."):
            u, var = c, c.variable(name[len("controller."):])
        elif name.startswith("plant."):
            u, var = p, p.variable(name[len("plant."):])
        elif name in p.vars and p.vars[name].causality == "output":
            u, var = p, p.vars[name]
        elif name in c.vars and c.vars[name].causality == "output":
            u, var = c, c.vars[name]
        else:
            raise CosimError(f"output {name!r}: neither FMU has an output of that name "
                             "(use 'controller.X' or 'plant.X' for other variables)")
        if var.type == "Real":
            return (u.index, REAL, var.valueReference)
        if var.type in ("Integer", "Enumeration"):
            return (u.index, INTEGER, var.valueReference)
        raise CosimError(f"output {name!r} is a {var.type}: only Real and Integer variables can be averaged")

    def _log(self, unit: int, status: int, category: str, message: str) -> None:
        name = self._units[unit].instance_name if unit < len(self._units) else str(unit)
        self.messages.append((_LABEL[unit] if unit in (0, 1) else str(unit), status, category, message))
        level = {0: logging.INFO, 1: logging.WARNING}.get(status, logging.ERROR)
        LOG.log(level, "[%s %s] %s", name, category, message)
        if self._user_log is not None:
            self._user_log(_LABEL[unit] if unit in (0, 1) else str(unit), status, category, message)

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
        slow = self._slow
        new = [T_ref, w_m, slow[2] if u_dc is None else u_dc, slow[3] if T_magnet is None else T_magnet,
               slow[4] if T_winding is None else T_winding]
        new = [float(x) for x in new]
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
        self._slow = new
        return AdvanceResult(mean=Sample(*mean), end=Sample(*end), t=self._b.k * self.h, k=self._b.k, rows=rows)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            if self._b is not None:
                self._b.close()
        finally:
            for u in self._units:
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
