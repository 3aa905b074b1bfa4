"""The IpmsmDrive FMU (controller + plant coupled inside at sample_time, inverter losses): the
fast path of every run, study and check, stepped at the vehicle side's step (10 ms):

    with DriveFmu("build/fmu/IpmsmDrive.fmu", w_m=100.0) as drive:
        r = drive.advance(0.01, T_ref=120.0, w_m=100.0, u_dc=355.0, T_magnet=353.15, T_winding=373.15)
        r.T_shaft, r.P_dc, r.E_dc, r.i_q      # a DriveStep: the FMU's outputs after the step

One fmi2SetReal of the five inputs and one fmi2DoStep per call, one fmi2GetReal of the Real
outputs DriveStep records and one fmi2GetInteger of its Integer ones (by name, from the model
description), each call's status checked: the per-step Python cost is four calls, whatever the
number of inner steps. The FMI 3.0 drive (build/fmu3/IpmsmDrive.fmu) is stepped the same way,
through its standard's functions (fmi3SetFloat64, fmi3DoStep, fmi3GetFloat64, fmi3GetInt32;
scenarios.cosim.standard). The reference loop (scenarios.cosim.reference) couples the two FMUs in
Python and returns the same DriveStep.
"""
from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, fields
from pathlib import Path

from scenarios.cosim.fmu import CosimError, Fmu
from scenarios.cosim.standard import OK, WARNING

INPUTS = ("T_ref", "w_m", "u_dc", "T_magnet", "T_winding")
#: the thermal network's boundary temperatures (contract, "Thermal"): inputs when the FMU has them
THERMAL_INPUTS = ("T_coolant", "T_ambient")


@dataclass(slots=True)
class DriveStep:
    """The IpmsmDrive's outputs after a step (INTERFACE.md, section IpmsmDrive): means over the
    step, integrals since the start, and the values at its end. SI units. Filled by name from the
    FMU's outputs of the same names: a new output of the drive is one line here. A field without a
    default is an output every drive FMU has; one with a default keeps it where the FMU has no
    such output."""
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
    # the thermal network (contract, "Thermal"; with it off: the temperature inputs and zeros); NaN
    # where the FMU has no such output. derating: the torque limit's thermal factor (1: none, as
    # from an FMU without it)
    theta_winding: float = math.nan
    theta_magnet: float = math.nan
    theta_stator_yoke: float = math.nan
    theta_stator_tooth: float = math.nan
    P_coolant: float = math.nan
    E_coolant: float = math.nan
    E_ambient: float = math.nan
    E_stored: float = math.nan
    derating: float = 1.0
    # the inverter's safe states (contract, "Faults"): the largest current magnitude since the last
    # fault began (0 before any), and the state the inverter is in (0 switching, 1 freewheeling, 2 ASC)
    i_peak: float = 0.0
    inverter_state: int = 0
    # the command's predicted loss P_cu + P_fe + P_inv (contract, "Least-loss control"); NaN where
    # the FMU has no such output
    P_loss_cmd: float = math.nan
    # Ohm, the stator phase resistance at the winding temperature over the step (the plant's, that of
    # its copper loss: |i|^2 = P_cu / (1.5 R_s_T)); NaN where the FMU has no such output
    R_s_T: float = math.nan


#: DriveStep's fields, in order; those every drive FMU must have
RECORD = tuple(f.name for f in fields(DriveStep))
REQUIRED = tuple(f.name for f in fields(DriveStep) if f.default is MISSING)


def recorded_outputs(unit: Fmu) -> dict[str, tuple[str, ...]]:
    """The unit's outputs that DriveStep records, by FMI type ("Real", "Integer"; "Float64",
    "Int32" in FMI 3.0), in the record's order; CosimError naming the first required one the unit
    lacks."""
    missing = [n for n in REQUIRED if n not in unit.vars or unit.vars[n].causality != "output"]
    if missing:
        raise CosimError(f"{unit.name} has no output {missing[0]!r}: not a drive FMU this record fits")
    by_type: dict[str, tuple[str, ...]] = {}
    for name in RECORD:
        v = unit.vars.get(name)
        if v is not None and v.causality == "output":
            by_type[v.type] = by_type.get(v.type, ()) + (name,)
    return by_type


#: IpmsmDrive's fault input (contract, "Faults"; its outputs inverter_state and i_peak are DriveStep's)
FAULT_INPUT = "fault"


class DriveFmu(Fmu):
    """One IpmsmDrive instance: parameters by name at construction (any parameter of the
    controller, the plant or the inverter, and sample_time), the inputs at t = 0; then advance(dt,
    ...) per vehicle step, dt a whole multiple of sample_time."""

    def __init__(self, path: str | Path, params: dict | None = None, T_ref: float = 0.0, w_m: float = 0.0,
                 u_dc: float = 355.0, T_magnet: float = 293.15, T_winding: float = 293.15,
                 instance_name: str = "drive", logging_on: bool = False, T_coolant: float | None = None,
                 T_ambient: float | None = None):
        super().__init__(path, instance_name, logging_on, initialise=False, **(params or {}))
        try:
            # the boundary temperatures are inputs only when given (None: the FMU's start values)
            boundary = {k: v for k, v in zip(THERMAL_INPUTS, (T_coolant, T_ambient)) if v is not None}
            self.inputs = INPUTS + tuple(boundary)
            self.set(**dict(zip(INPUTS, (T_ref, w_m, u_dc, T_magnet, T_winding))), **boundary)
            self.exit_initialization()
            self.sample_time = self.get("sample_time")
            self._boundary = tuple(boundary.values())
            # the value references and values every advance() passes, made once: the inputs, and
            # the recorded outputs by type (one Get call each), each with its Get function
            real = self.api.NEUTRAL["Real"]
            self._set_inputs, self._step = self.api.setter(real), self.api.do_step
            self._u_vr, self._u = self.vrs(*self.inputs), (self.c_type("Real") * len(self.inputs))()
            self._outputs = [(names, self.api.getter(kind), self.vrs(*names), (self.api.KINDS[kind][2] * len(names))(),
                              f"{self.api.PREFIX}Get{kind} of the outputs")
                             for kind, names in recorded_outputs(self).items()]
            self.outputs = tuple(n for names, *_ in self._outputs for n in names)
            self.has_fault = FAULT_INPUT in self.vars   # contract, "Faults"
            self.fault = False
            if self.has_fault:
                self._fault_vr = self.vrs(FAULT_INPUT)
        except BaseException:
            self.close()
            raise

    def set_fault(self, on: bool) -> None:
        """IpmsmDrive's `fault` input from the next step on (the inverter stops switching, or
        switches again); an FMU without it: CosimError."""
        if not self.has_fault:
            raise CosimError(f"{self.path} has no `fault` input (contract, \"Faults\"): rebuild the FMUs")
        if on != self.fault:
            self.write(self._fault_vr, (self.c_type("Boolean") * 1)(on), "Boolean")
            self.fault = on

    def advance(self, dt: float, T_ref: float, w_m: float, u_dc: float, T_magnet: float,
                T_winding: float) -> DriveStep:
        """One step of dt (a whole multiple of sample_time) with the inputs held over it."""
        c = self.c
        self._u[:] = (T_ref, w_m, u_dc, T_magnet, T_winding, *self._boundary)
        if (status := self._set_inputs(c, self._u_vr, len(self._u), self._u)) > WARNING:
            self.fail(f"{self.api.PREFIX}Set{self.api.NEUTRAL['Real']} of the inputs", status)
        status = self._step(c, self.t, dt)
        if status != OK:
            raise CosimError(f"IpmsmDrive: {self.api.PREFIX}DoStep from t = {self.t:.9g} s by {dt:.9g} s returned "
                             f"status {status}; the FMU says: {self.last_messages()}")
        self.t += dt
        values = {}
        for names, get, vrs, out, what in self._outputs:
            if (status := get(c, vrs, len(out), out)) > WARNING:
                self.fail(what, status)
            values.update(zip(names, out))
        return DriveStep(**values)


def steps_of(dt: float, sample_time: float) -> int:
    """dt / sample_time, checked to be whole (the FMU refuses other steps)."""
    n = round(dt / sample_time)
    if n < 1 or not math.isclose(n * sample_time, dt, rel_tol=1e-9):
        raise ValueError(f"dt = {dt} s is not a whole multiple of sample_time = {sample_time} s")
    return n
