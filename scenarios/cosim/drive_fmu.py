"""The IpmsmDrive FMU (controller + plant coupled inside at sample_time, inverter losses) through
plain fmpy calls, for the vehicle side at its own step (10 ms):

    with DriveFmu("build/fmu/IpmsmDrive.fmu", w_m=100.0) as drive:
        r = drive.advance(0.01, T_ref=120.0, w_m=100.0, u_dc=355.0, T_magnet=353.15, T_winding=373.15)
        r.T_shaft, r.P_dc, r.E_dc, r.i_q      # a DriveStep: the FMU's outputs after the step

One fmi2SetReal of the five inputs and one fmi2DoStep per call, one fmi2GetReal of every Real
output and one fmi2GetInteger of the region: the per-step Python cost is four calls, whatever the
number of inner steps. They are fmpy's fmi2* functions on ctypes arrays made once per instance
(fmpy's setReal/getReal build new arrays at every call, which costs 2-5 times the call itself).
Messages the FMU logs go to the logging module ("scenarios.cosim.drive_fmu") and to `messages`; a
failed call raises CosimError with the FMU's last messages.
"""
from __future__ import annotations

import logging
import math
import shutil
from collections import deque
from collections.abc import Mapping
from ctypes import c_double, c_int, c_uint
from dataclasses import dataclass, fields
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2OK

from scenarios.cosim.master import AdvanceResult, CosimError, Sample

LOG = logging.getLogger("scenarios.cosim.drive_fmu")
INPUTS = ("T_ref", "w_m", "u_dc", "T_magnet", "T_winding")


@dataclass(slots=True)
class DriveStep:
    """The IpmsmDrive's outputs after a step (INTERFACE.md, section IpmsmDrive): means over the
    step, integrals since the start, and the values at its end. SI units."""
    T_shaft: float
    T_e: float
    i_dc: float
    P_dc: float
    P_mech: float
    P_cu: float
    P_fe: float
    P_inv: float
    P_elec: float
    E_dc: float
    E_mech: float
    E_cu: float
    E_fe: float
    E_inv: float
    T_cmd: float
    T_max: float
    i_d: float
    i_q: float
    i_d_ref: float
    i_q_ref: float
    u_ratio: float
    region: int


_REALS = tuple(f.name for f in fields(DriveStep) if f.name != "region")


class DriveFmu:
    """One IpmsmDrive instance: parameters by name at construction (any parameter of the
    controller, the plant or the inverter, and sample_time), the inputs at t = 0; then advance(dt,
    ...) per vehicle step, dt a whole multiple of sample_time."""

    def __init__(self, path: str | Path, params: Mapping | None = None, T_ref: float = 0.0, w_m: float = 0.0,
                 u_dc: float = 355.0, T_magnet: float = 293.15, T_winding: float = 293.15,
                 instance_name: str = "drive", logging_on: bool = False):
        self.path = Path(path)
        self.md = read_model_description(str(self.path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.messages: deque = deque(maxlen=200)  # (status, category, message), the latest
        self._dir = extract(str(self.path))
        self.fmu = None
        self.t = 0.0
        try:
            self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self._dir,
                                 modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=instance_name,
                                 fmiCallLogger=None)
            self.fmu.instantiate(loggingOn=logging_on, callbacks=self._callbacks())
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
            for name, value in (params or {}).items():
                self._set_parameter(name, value)
            self._input_vrs = [self.vars[n].valueReference for n in INPUTS]
            self.fmu.setReal(self._input_vrs, [float(T_ref), float(w_m), float(u_dc), float(T_magnet),
                                               float(T_winding)])
            self._call("fmi2ExitInitializationMode", self.fmu.exitInitializationMode)
            self.sample_time = self.fmu.getReal([self.vars["sample_time"].valueReference])[0]
            # the value references and values every advance() passes (fmi2ValueReference, fmi2Real,
            # fmi2Integer arrays)
            self._u_vr, self._u = (c_uint * len(INPUTS))(*self._input_vrs), (c_double * len(INPUTS))()
            self._y_vr = (c_uint * len(_REALS))(*(self.vars[n].valueReference for n in _REALS))
            self._y = (c_double * len(_REALS))()
            self._region_vr, self._region = (c_uint * 1)(self.vars["region"].valueReference), (c_int * 1)()
        except BaseException:
            self.close()
            raise

    def _callbacks(self):
        """Callbacks whose logger keeps the FMU's messages (and passes them to logging)."""
        from fmpy.fmi2 import defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

        def logger(env, instance, status, category, message):
            # the FMU doubles '%' for printf-style loggers: undo it as printf would
            text = (message or b"").decode(errors="replace").replace("%%", "%")
            cat = (category or b"").decode(errors="replace")
            self.messages.append((status, cat, text))
            LOG.log(logging.INFO if status == fmi2OK else logging.WARNING if status == 1 else logging.ERROR,
                    "[IpmsmDrive %s] %s", cat, text)

        self._logger = fmi2CallbackLoggerTYPE(logger)  # kept alive as long as the instance
        cb = fmi2CallbackFunctions()
        cb.logger = self._logger
        cb.allocateMemory = defaultCallbacks.allocateMemory
        cb.freeMemory = defaultCallbacks.freeMemory
        self._cb = cb
        return cb

    def last_messages(self, n: int = 3) -> str:
        return " | ".join(m for _, _, m in list(self.messages)[-n:])

    def _set_parameter(self, name: str, value) -> None:
        v = self.vars.get(name)
        if v is None or v.causality not in ("parameter", "input"):
            raise CosimError(f"IpmsmDrive has no parameter {name!r}")
        vr = [v.valueReference]
        if v.type == "Real":
            self.fmu.setReal(vr, [float(value)])
        elif v.type == "Integer":
            self.fmu.setInteger(vr, [int(value)])
        elif v.type == "Boolean":
            self.fmu.setBoolean(vr, [bool(value)])
        else:
            self.fmu.setString(vr, [str(value)])

    def _call(self, what: str, f, *args):
        try:
            return f(*args)
        except Exception as e:
            raise CosimError(f"IpmsmDrive: {what} failed at t = {self.t:.9g} s: {e}; the FMU says: "
                             f"{self.last_messages()}") from None

    def advance(self, dt: float, T_ref: float, w_m: float, u_dc: float, T_magnet: float,
                T_winding: float) -> DriveStep:
        """One step of dt (a whole multiple of sample_time) with the inputs held over it."""
        fmu = self.fmu
        c = fmu.component
        self._u[:] = (T_ref, w_m, u_dc, T_magnet, T_winding)
        fmu.fmi2SetReal(c, self._u_vr, len(INPUTS), self._u)
        status = fmu.fmi2DoStep(c, self.t, dt, 1)
        if status != fmi2OK:
            raise CosimError(f"IpmsmDrive: fmi2DoStep from t = {self.t:.9g} s by {dt:.9g} s returned status "
                             f"{status}; the FMU says: {self.last_messages()}")
        self.t += dt
        fmu.fmi2GetReal(c, self._y_vr, len(_REALS), self._y)
        fmu.fmi2GetInteger(c, self._region_vr, 1, self._region)
        return DriveStep(*self._y[:], region=self._region[0])

    def close(self) -> None:
        if self.fmu is not None:
            try:
                self.fmu.terminate()
            except Exception:
                pass
            try:
                self.fmu.freeInstance()
            except Exception:
                pass
            self.fmu = None
        if self._dir:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def steps_of(dt: float, sample_time: float) -> int:
    """dt / sample_time, checked to be whole (the FMU refuses other steps)."""
    n = round(dt / sample_time)
    if n < 1 or not math.isclose(n * sample_time, dt, rel_tol=1e-9):
        raise ValueError(f"dt = {dt} s is not a whole multiple of sample_time = {sample_time} s")
    return n


@dataclass(slots=True)
class DriveAdvanceResult(AdvanceResult):
    """AdvanceResult of the drive FMU, with its inverter loss (W, mean over the step)."""
    P_inverter: float


class DriveAsCosim:
    """IpmsmDrive behind DriveCosim's interface (scenarios.cosim.master): advance(n_steps, inputs) is one
    fmi2DoStep of n_steps sample times, and returns the Samples the vehicle side reads. The drive
    outputs the means of the contract; a Sample's fields it has no output for are derived
    (i_abs_sq = P_cu / (1.5 R) with R at the held winding temperature, exact) or NaN (i_abs,
    iterations; the mean i_d, i_q are the end values). Its inverter loss is the FMU's
    (`P_inverter`), not scenarios/inverter.py's."""

    backend_name = "drive"

    def __init__(self, drive_fmu: str | Path, controller_params: Mapping | None = None,
                 plant_params: Mapping | None = None, h: float | None = None, w_m: float = 0.0,
                 u_dc: float = 355.0, T_magnet: float = 293.15, T_winding: float = 293.15, T_ref: float = 0.0,
                 inverter_params: Mapping | None = None):
        params = {**(controller_params or {}), **(plant_params or {}), **(inverter_params or {})}
        if h is not None:
            params["sample_time"] = h
        self.drive = DriveFmu(drive_fmu, params, T_ref=T_ref, w_m=w_m, u_dc=u_dc, T_magnet=T_magnet,
                              T_winding=T_winding)
        self.h = self.drive.sample_time
        self.k = 0
        get = self.drive.fmu.getReal
        self._R_s, self._alpha_cu, self._T_winding_ref = get(
            [self.drive.vars[n].valueReference for n in ("R_s", "alpha_cu", "T_winding_ref")])

    @property
    def t(self) -> float:
        return self.k * self.h

    def advance(self, n_steps: int, T_ref: float, w_m: float, u_dc: float, T_magnet: float,
                T_winding: float) -> DriveAdvanceResult:
        s = self.drive.advance(n_steps * self.h, T_ref, w_m, u_dc, T_magnet, T_winding)
        self.k += n_steps
        R = self._R_s * (1.0 + self._alpha_cu * (T_winding - self._T_winding_ref))
        i_abs_sq = s.P_cu / (1.5 * R) if R > 0.0 else math.nan
        nan, region = math.nan, float(s.region)
        # Sample's fields in order (positional: a keyword call costs three times as much, per step):
        # T_shaft, T_e, P_elec, P_mech, P_cu, P_fe, i_d, i_q, i_abs, i_abs_sq, T_cmd, T_max, region,
        # iterations, u_ratio
        mean = Sample(s.T_shaft, s.T_e, s.P_elec, s.P_mech, s.P_cu, s.P_fe, s.i_d, s.i_q, nan, i_abs_sq,
                      s.T_cmd, s.T_max, region, nan, s.u_ratio)
        end = Sample(s.T_shaft, s.T_e, s.P_elec, s.P_mech, s.P_cu, s.P_fe, s.i_d, s.i_q, math.hypot(s.i_d, s.i_q),
                     s.i_d * s.i_d + s.i_q * s.i_q, s.T_cmd, s.T_max, region, nan, s.u_ratio)
        return DriveAdvanceResult(mean, end, self.t, self.k, 0, s.P_inv)

    def close(self) -> None:
        self.drive.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
