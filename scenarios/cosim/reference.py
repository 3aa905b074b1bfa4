"""The reference loop: IpmsmController and IpmsmPlant coupled in Python by the drive's coupling
description (fmu_src/coupling/ipmsm_drive.coupling, its semantics stated there), by variable
name, each step as the Modelica Reference-FMUs' simulate_fmi2_cs.c steps an FMU: set the inputs,
fmi2DoStep(t_k, h) with t_k = k h, read the outputs. It returns IpmsmDrive's step record
(DriveStep), so a run takes either (`--backend reference`) and the tests hold the drive FMU
against it. A dozen FMI calls from Python per 100 us: slow; IpmsmDrive is the fast path.

    with ReferenceDrive(controller_fmu, plant_fmu, w_m=100.0) as ref:
        s = ref.advance(0.01, T_ref=120.0, w_m=100.0, u_dc=355.0, T_magnet=353.15, T_winding=373.15)

The record, by name (INTERFACE.md, IpmsmDrive): a mean over the step is its integral's increase
(the plant's E_* and T_e_impulse) over the step; the inverter's loss the mean of the plant's P_inv
after each inner step (as IpmsmDrive reads it; docs/validation.md: the inverter); every other field
the output of that name of the first unit that has it, at the end of the step.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path

from scenarios.cosim.coupling import DRIVE, Coupling
from scenarios.cosim.drive_fmu import RECORD, DriveStep, steps_of
from scenarios.cosim.fmu import CosimError, Fmu

#: a mean over the step (DriveStep's name) -> the plant's integral since the start whose increase it is
MEAN_OF = {"T_e": "T_e_impulse", "P_elec": "E_elec", "P_mech": "E_mech", "P_cu": "E_cu", "P_fe": "E_fe",
           "P_coolant": "E_coolant"}
#: the drive's own definitions (INTERFACE.md, IpmsmDrive) of what no unit outputs
DEFINED = ("T_shaft", "P_dc", "i_dc", "E_dc", "P_inv")
START = dict(T_ref=0.0, w_m=0.0, u_dc=355.0, T_magnet=293.15, T_winding=293.15)  # the FMUs' start values


class ReferenceDrive:
    """The drive's two units coupled at h (None: the description's step). Parameters by name per
    unit; the external inputs (T_ref, w_m, u_dc, T_magnet, T_winding) at t = 0. clock: k -> (t_k,
    h_k) passed to fmi2DoStep instead of (k h, h), to reproduce another master's clock."""

    def __init__(self, controller_fmu: str | Path, plant_fmu: str | Path, controller_params: Mapping | None = None,
                 plant_params: Mapping | None = None, h: float | None = None, coupling: Coupling = DRIVE,
                 logging_on: bool = False,
                 clock: Callable[[int], tuple[float, float]] | None = None, **start: float):
        self.h = self.sample_time = coupling.step if h is None else h
        if not (isinstance(self.h, (int, float)) and math.isfinite(self.h) and self.h > 0):
            raise ValueError(f"h = {self.h!r}: must be a finite number > 0")
        if set(start) - set(START):
            raise TypeError(f"unknown start input(s) {sorted(set(start) - set(START))}: one of {', '.join(START)}")
        self.coupling, self.k, self._clock, self.held = coupling, 0, clock, {**START, **start}
        paths = dict(controller=controller_fmu, plant=plant_fmu)
        params = dict(controller=controller_params or {}, plant=plant_params or {})
        self.units: dict[str, Fmu] = {}
        try:
            for u in coupling.units:  # instantiated, parameters set, in Initialization Mode
                f = self.units[u.role] = Fmu(paths[u.role], u.role, logging_on, False, **params[u.role])
                if f.name != u.model_identifier:
                    raise CosimError(f"the {u.role} must be {u.model_identifier}, {f.path} is {f.name}")
            for port in [*(p for e in coupling.inputs for p in e.targets),
                         *(p for c in coupling.connections for p in (c.source, c.target))]:
                self.units[port.unit].variable(port.variable)  # every name resolves, before any step
            for role, f in self.units.items():  # in order: inputs, exit initialisation (the plant first)
                f.set(**self._external(role), **self._fed(role))
                f.exit_initialization()
            self._record_from = {n: next((r for r, f in self.units.items() if n in f.vars), None)
                                 for n in RECORD if n not in MEAN_OF and n not in DEFINED}
            self._integrals = self._plant(*MEAN_OF.values())
        except BaseException:
            self.close()
            raise

    def _external(self, role: str) -> dict:
        """The unit's inputs fed by the external inputs, by name: their held values."""
        return {p.variable: self.held[e.name] for e in self.coupling.inputs for p in e.targets if p.unit == role}

    def _fed(self, role: str) -> dict:
        """The unit's inputs fed by the other (initialised) units' outputs, by name: their values now."""
        fed = {}
        for source, f in self.units.items():
            links = [c for c in self.coupling.connections if c.target.unit == role and c.source.unit == source]
            if links and f.initialised:
                fed.update(zip((c.target.variable for c in links), f.values(*(c.source.variable for c in links))))
        return fed

    def _plant(self, *names: str) -> dict:
        return dict(zip(names, self.units["plant"].values(*names)))

    def get(self, *names: str):
        """Variables by name: "role.variable", or a variable of the first unit that has it."""
        out = [(self.units[n.partition(".")[0]] if "." in n else next(f for f in self.units.values() if n in f.vars))
               .get(n.rpartition(".")[2]) for n in names]
        return out[0] if len(out) == 1 else out

    def advance(self, dt: float, T_ref: float, w_m: float, u_dc: float, T_magnet: float,
                T_winding: float) -> DriveStep:
        """dt (a whole number n of steps h) with the external inputs held: n coupled steps."""
        n, h = steps_of(dt, self.h), self.h
        self.held.update(T_ref=T_ref, w_m=w_m, u_dc=u_dc, T_magnet=T_magnet, T_winding=T_winding)
        for role, f in self.units.items():  # a refused input raises with k unchanged: fix it and call again
            f.set(**self._external(role))
        P_inv = 0.0
        for _ in range(n):
            fed = {role: self._fed(role) for role in self.units}  # every output after the previous step
            for role, f in self.units.items():
                f.set(**fed[role])
            t, h_k = (self.k * h, h) if self._clock is None else self._clock(self.k)
            for f in self.units.values():
                f.step_from(t, h_k)  # f.t: the step's start (a failure's message names it)
            self.k += 1
            P_inv += self.units["plant"].get("P_inv")
        return self._record(n * h, P_inv / n)

    def _record(self, duration: float, P_inv: float) -> DriveStep:
        """The step's DriveStep, by name (the module's docstring)."""
        now = self._plant(*MEAN_OF.values())
        r = {mean: (now[e] - self._integrals[e]) / duration for mean, e in MEAN_OF.items()}
        self._integrals = now
        for name, role in self._record_from.items():
            if role is not None:
                r[name] = self.units[role].get(name)
        w_m, u_dc = self.held["w_m"], self.held["u_dc"]
        r.update(P_inv=P_inv, P_dc=r["P_elec"] + P_inv, E_dc=now["E_elec"] + r["E_inv"],
                 T_shaft=r["T_e"] - r["P_fe"] / w_m if w_m != 0.0 else r["T_e"])
        r["i_dc"] = r["P_dc"] / u_dc
        return DriveStep(**r)

    def save_state(self):
        """Both units' states and the loop's own (its step count, the plant's integrals): to go
        back to; free it with free_state."""
        return ({r: f.save_state() for r, f in self.units.items()}, self.k, list(self._integrals), self._E_coolant,
                dict(self.held))

    def restore_state(self, saved) -> None:
        units, self.k, integrals, self._E_coolant, held = saved
        for role, f in self.units.items():
            f.restore_state(units[role])
        self._integrals, self.held = list(integrals), dict(held)

    def free_state(self, saved) -> None:
        for role, f in self.units.items():
            f.free_state(saved[0][role])

    def close(self) -> None:
        for f in reversed(list(self.units.values())):
            f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
