"""The one Python handle on a co-simulation FMU (fmpy's FMU2Slave or FMU3Slave underneath): variables by name,
value references resolved once, the FMU's log kept and passed to logging, every failed call a
CosimError that quotes what the FMU logged.

    with Fmu("build/fmu/IpmsmController.fmu", method="ferrari") as c:   # parameters; initialised
        c.set(T_ref=100.0, w_m=300.0)
        c.do_step(0.0, 1e-4)
        c.get("i_d_ref", "i_q_ref")

Fmu(..., initialise=False) stays in Initialization Mode (parameters set) until exit_initialization():
a master initialising several units in order needs that. The per-step paths (the drive FMU, the
reference loop) call the FMU's functions on ctypes arrays made once (`vrs`, `read`, `write`): fmpy's
getReal/setReal build new arrays at every call, which costs 2-5 times the call itself.

FMI 2.0 and FMI 3.0 FMUs alike (fmpy's FMU2Slave or FMU3Slave, by the model description's
fmiVersion): what differs between the two standards is in scenarios.cosim.standard.
"""
from __future__ import annotations

import logging
import shutil
from collections import deque
from collections.abc import Mapping
from ctypes import c_uint
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from scenarios.cosim.standard import FATAL, OK, WARNING, Fmi2, for_version

LOG = logging.getLogger("scenarios.cosim")
_LEVEL = {OK: logging.INFO, WARNING: logging.WARNING}


def set_values(fmu: FMU2Slave, variables: Mapping, **values) -> None:
    """Set variables by name (variables: name -> ScalarVariable), each through its type's
    fmi2Set<Type>, the value converted to that type."""
    for name, value in values.items():
        v = variables[name]
        kind, convert, _ = Fmi2.KINDS[v.type]
        getattr(fmu, "set" + kind)([v.valueReference], [convert(value)])


def get_values(fmu: FMU2Slave, variables: Mapping, *names: str):
    """The named variables' values, each through its type's fmi2Get<Type>: one value for one
    name, else a list."""
    out = [getattr(fmu, "get" + Fmi2.KINDS[variables[n].type][0])([variables[n].valueReference])[0] for n in names]
    return out[0] if len(out) == 1 else out


def model_description(path: Path):
    """fmpy's model description of the FMU at `path`; a file that is no FMU (not a zip, no
    modelDescription.xml, a malformed one): InputError naming it and --build (exit 2)."""
    from scenarios.core.boundary import InputError, printable
    try:
        return read_model_description(str(path))
    except Exception as e:  # noqa: BLE001 - zipfile's, ElementTree's and fmpy's own refusals alike
        raise InputError(path, "--build", f"an FMU: a zip archive with a valid modelDescription.xml (rebuild it: "
                         f"cmake --build build); {type(e).__name__}: {printable(str(e))}") from None


class CosimError(RuntimeError):
    """An FMI call failed (the message names the FMU, the call and the time, and quotes the FMU's
    log), or a unit was used wrongly."""


class Fmu:
    """One instance of a co-simulation FMU: set-up, parameters (by name, any type) and, unless
    initialise=False, fmi2ExitInitializationMode at construction. A context manager (frees it)."""

    def __init__(self, path: str | Path, instance_name: str | None = None, logging: bool = False,
                 initialise: bool = True, keep_log: int | None = 200, quiet: bool = False, **parameters):
        """keep_log: the latest messages kept (None: all); quiet: the FMU's log kept, not passed to
        logging (a caller that reports it itself)."""
        self.path = Path(path)
        self.md = model_description(self.path)
        self.name = self.md.coSimulation.modelIdentifier
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.messages: deque = deque(maxlen=keep_log)  # (status, category, message), the latest
        self._quiet = quiet
        self.t = 0.0
        self.fmu = None
        self.initialised = False  # fmi2Terminate is allowed only once initialisation has succeeded
        standard = for_version(self.md.fmiVersion)
        if standard is None:
            raise CosimError(f"{self.path} is an FMI {self.md.fmiVersion} FMU: only FMI 2.0 and FMI 3.0 are run")
        self._dir = extract(str(self.path))
        try:
            self.api = standard(self.md, self._dir, instance_name or self.md.modelName, logging, self._log)
            self.fmu, self.c, self.dll = self.api.slave, self.api.c, self.api.dll
            for function, args in self.api.start_calls():
                self.call(function, *args)
            self.set(**parameters)
            if initialise:
                self.exit_initialization()
        except BaseException:
            self.close()
            raise

    def _log(self, status, category, message) -> None:
        """The FMU's logger (either standard's): kept, and passed to logging unless quiet."""
        text = (message or b"").decode(errors="replace").replace("%%", "%")  # as printf would
        self.messages.append((status, (category or b"").decode(errors="replace"), text))
        if not self._quiet:
            LOG.log(_LEVEL.get(status, logging.ERROR), "[%s] %s", self.name, text)

    def last_messages(self, n: int = 3) -> str:
        return " | ".join(m for _, _, m in list(self.messages)[-n:]) or "(the FMU logged no message)"

    def fail(self, what: str, status: int) -> None:
        raise CosimError(f"{self.name}: {what} failed at t = {self.t:.9g} s (status {status}); "
                         f"the FMU says: {self.last_messages()}")

    def call(self, function: str, *args) -> None:
        """function(instance, *args) (its full name: fmi2..., fmi3...), its status checked."""
        status = getattr(self.dll, function)(self.c, *args)
        if status > WARNING:
            self.fail(function, status)

    def exit_initialization(self) -> None:
        self.call(self.api.EXIT_INITIALIZATION)
        self.initialised = True

    def variable(self, name: str):
        try:
            return self.vars[name]
        except KeyError:
            raise CosimError(f"{self.name} has no variable {name!r}") from None

    def vrs(self, *names: str):
        """The variables' value references, as an fmi2ValueReference (fmi3ValueReference) array."""
        return (c_uint * len(names))(*(self.variable(n).valueReference for n in names))

    def read(self, vrs, out, kind: str = "Real") -> None:
        """The Get function of kind ("Real", "Integer", "Boolean": Float64, Int32, Boolean in FMI
        3.0) of the value references vrs (an array from `vrs`) into out, an array of their length
        and the kind's C type (made once by the caller: the per-step paths)."""
        if (status := self.api.getter(self.api.NEUTRAL[kind])(self.c, vrs, len(vrs), out)) > WARNING:
            self.fail(f"{self.api.PREFIX}Get{self.api.NEUTRAL[kind]}", status)

    def write(self, vrs, values, kind: str = "Real") -> None:
        """As read, the Set function: values (an array of the kind's C type) to vrs."""
        if (status := self.api.setter(self.api.NEUTRAL[kind])(self.c, vrs, len(vrs), values)) > WARNING:
            self.fail(f"{self.api.PREFIX}Set{self.api.NEUTRAL[kind]}", status)

    def c_type(self, kind: str):
        """The C type of kind's values ("Real", "Integer", "Boolean") in this FMU's standard."""
        return self.api.KINDS[self.api.NEUTRAL[kind]][2]

    def set(self, **values) -> None:
        """Variables by name (parameters, inputs), each converted to its type: one fmi2Set<Type>
        per type."""
        by_kind: dict[str, tuple[list, list]] = {}
        for name, value in values.items():
            v = self.variable(name)
            if v.causality not in ("parameter", "input"):
                raise CosimError(f"{self.name}.{name} is {v.causality}: only parameters and inputs are set")
            kind, convert, _ = self.api.KINDS[v.type]
            vrs, xs = by_kind.setdefault(kind, ([], []))
            vrs.append(v.valueReference)
            xs.append(convert(value))
        try:
            for kind, (vrs, xs) in by_kind.items():
                getattr(self.fmu, "set" + kind)(vrs, xs)
        except Exception as e:  # fmpy raises on a status above fmi2Warning
            raise CosimError(f"{self.name}: setting {', '.join(values)} failed ({e}); the FMU says: "
                             f"{self.last_messages()}") from None

    def get(self, *names: str):
        """The variables' values (Real, Integer, Boolean, String): one value for one name, else a
        list; one fmi2Get<Type> per type."""
        out = self.values(*names)
        return out[0] if len(out) == 1 else out

    def values(self, *names: str) -> list:
        """The variables' values, a list (as get())."""
        by_kind: dict[str, list[int]] = {}
        for i, name in enumerate(names):
            by_kind.setdefault(self.api.KINDS[self.variable(name).type][0], []).append(i)
        out: list = [None] * len(names)
        try:
            for kind, where in by_kind.items():
                got = getattr(self.fmu, "get" + kind)([self.vars[names[i]].valueReference for i in where])
                for i, x in zip(where, got):
                    out[i] = x
        except Exception as e:  # fmpy raises on a status above fmi2Warning
            raise CosimError(f"{self.name}: getting {', '.join(names)} failed ({e}); the FMU says: "
                             f"{self.last_messages()}") from None
        return out

    def step_from(self, t: float, h: float) -> None:
        """DoStep from t by h, its status checked; self.t stays t, the step's start (a master that
        keeps its own clock, scenarios.cosim.reference)."""
        self.t = t
        if (status := self.api.do_step(self.c, t, h)) > WARNING:
            self.fail(f"{self.api.PREFIX}DoStep", status)

    def do_step(self, t: float, h: float) -> None:
        self.step_from(t, h)
        self.t = t + h

    step = do_step

    def save_state(self):
        """fmi2GetFMUstate (fmi3GetFMUState): a copy of the instance's state (and its time) to go
        back to; free it with free_state."""
        return self.api.get_state(), self.t

    def restore_state(self, saved) -> None:
        """fmi2SetFMUstate (fmi3SetFMUState): the instance as it was when `saved` was taken."""
        self.api.set_state(saved[0])
        self.t = saved[1]

    def free_state(self, saved) -> None:
        self.api.free_state(saved[0])

    def close(self) -> None:
        if self.fmu is not None:
            fatal = any(s == FATAL for s, _, _ in self.messages)
            try:
                if self.initialised and not fatal:
                    self.fmu.terminate()
            except Exception:  # noqa: S110 - a unit that failed may refuse to terminate: free it anyway
                pass
            try:
                self.fmu.freeInstance()
            finally:
                self.fmu = None
        if self._dir:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
