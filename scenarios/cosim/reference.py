"""The reference loop: IpmsmController and IpmsmPlant coupled in Python by the drive's coupling
description (fmu_src/coupling/ipmsm_drive.coupling, its semantics stated there), by variable
name, each step as the Modelica Reference-FMUs' simulate_fmi2_cs.c steps an FMU: set the inputs,
fmi2DoStep(t_k, h) with t_k = k h, read the outputs. It returns IpmsmDrive's step record
(DriveStep), so a run takes either (`--backend fmpy`) and the tests hold the drive FMU against it.
Six FMI calls from Python per 100 us: slow; IpmsmDrive is the fast path.

    with ReferenceDrive(controller_fmu, plant_fmu, w_m=100.0) as ref:
        s = ref.advance(0.01, T_ref=120.0, w_m=100.0, u_dc=355.0, T_magnet=353.15, T_winding=373.15)

The inverter's loss is the plant's (its P_inv, read after each inner step, as IpmsmDrive reads it;
docs/validation.md: the inverter).
"""
from __future__ import annotations

import ctypes
import math
from collections.abc import Callable, Mapping
from ctypes import c_double, c_int
from pathlib import Path

from scenarios.cosim.coupling import DRIVE, Coupling
from scenarios.cosim.drive_fmu import DriveStep, steps_of
from scenarios.cosim.fmu import FMI2_WARNING, CosimError, Fmu

#: the plant's integrals since the start (exact over each step): a step's means are their increases
PLANT_INTEGRALS = ("E_elec", "E_mech", "E_cu", "E_fe", "T_e_impulse", "E_inv")
CONTROLLER_END = ("T_cmd", "T_max", "i_d_ref", "i_q_ref", "u_ratio")
#: the plant's thermal network at the end of a step (contract, "Thermal"): P_coolant, the step's
#: mean as IpmsmDrive gives it, is E_coolant's increase over the step
PLANT_THERMAL = ("theta_winding", "theta_magnet", "theta_stator_yoke", "theta_stator_tooth", "E_coolant",
                 "E_ambient", "E_stored")
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
        self.k, self._clock, self.held = 0, clock, {**START, **start}
        paths, params = dict(controller=controller_fmu, plant=plant_fmu), \
            dict(controller=controller_params or {}, plant=plant_params or {})
        self.units: dict[str, Fmu] = {}
        try:
            for u in coupling.units:  # instantiated, set up, parameters set, in Initialization Mode
                f = self.units[u.role] = Fmu(paths[u.role], u.role, logging_on, False, **params[u.role])
                if f.name != u.model_identifier:
                    raise CosimError(f"the {u.role} must be {u.model_identifier}, {f.path} is {f.name}")
            self._resolve(coupling)
            ready = set()
            for role, f in self.units.items():  # in order: inputs, exit, outputs (the plant first)
                f.set(**{v: self.held[x] for x, v in self.external[role]},
                      **{v: self.out[src][1][i] for v, src, i in self.feeds[role] if src in ready})
                f.exit_initialization()
                f.read(*self.out[role][:2])
                ready.add(role)
            plant, controller = self.units["plant"], self.units["controller"]
            self._integral = plant.vrs(*PLANT_INTEGRALS), (c_double * len(PLANT_INTEGRALS))()
            self._end = controller.vrs(*CONTROLLER_END), (c_double * len(CONTROLLER_END))()
            self._region = controller.vrs("region"), (c_int * 1)()
            self._integrals = self._plant_integrals()
            self._E_coolant = plant.get("E_coolant") if "E_coolant" in plant.vars else 0.0
        except BaseException:
            self.close()
            raise

    def _resolve(self, c: Coupling) -> None:
        """By name: per unit its external inputs, the outputs read after each step (one buffer per
        unit, each receiver's share contiguous) and the feeds (the receiver's inputs, a slice of
        the sender's buffer)."""
        self.external = {r: [(e.name, p.variable) for e in c.inputs for p in e.targets if p.unit == r] for r in c.roles}
        names = {r: [] for r in c.roles}
        self.feeds = {r: [] for r in c.roles}  # receiver -> [(input, sender, index in its buffer)]
        for to in c.roles:
            for conn in (x for x in c.connections if x.target.unit == to):
                names[conn.source.unit].append(conn.source.variable)
                self.feeds[to].append((conn.target.variable, conn.source.unit, len(names[conn.source.unit]) - 1))
        names["plant"].append("P_inv")  # read after each inner step too: the inverter's loss over it
        self.out = {r: (self.units[r].vrs(*names[r]), (c_double * len(names[r]))()) for r in c.roles}
        self._i = [names["plant"].index(x) for x in ("i_d", "i_q", "P_inv")]
        self._sets = []
        for to, feeds in self.feeds.items():
            f = self.units[to]
            for src in dict.fromkeys(s for _, s, _ in feeds):
                mine = [(v, i) for v, s, i in feeds if s == src]
                at = ctypes.addressof(self.out[src][1]) + mine[0][1] * ctypes.sizeof(c_double)
                self._sets.append((f, f.vrs(*(v for v, _ in mine)), ctypes.cast(at, ctypes.POINTER(c_double))))

    def get(self, *names: str):
        """Variables by name: "role.variable", or a variable of the first unit that has it."""
        out = [(self.units[n.partition(".")[0]] if "." in n else next(f for f in self.units.values() if n in f.vars))
               .get(n.rpartition(".")[2]) for n in names]
        return out[0] if len(out) == 1 else out

    def _plant_integrals(self) -> list[float]:
        self.units["plant"].read(*self._integral)
        return self._integral[1][:]

    def advance(self, dt: float, T_ref: float, w_m: float, u_dc: float, T_magnet: float,
                T_winding: float) -> DriveStep:
        """dt (a whole number n of steps h) with the external inputs held: n coupled steps."""
        n, h, k = steps_of(dt, self.h), self.h, self.k
        self.held.update(T_ref=T_ref, w_m=w_m, u_dc=u_dc, T_magnet=T_magnet, T_winding=T_winding)
        for role, f in self.units.items():  # a refused input raises with k unchanged: fix it and call again
            f.set(**{v: self.held[x] for x, v in self.external[role]})
        reads = [(f, *self.out[role]) for role, f in self.units.items()]
        plant, inv = self.out["plant"][1], self._i[2]
        s_inv = 0.0
        try:
            for _ in range(n):
                for f, vrs, values in self._sets:  # the outputs after the previous step
                    if (status := f.dll.fmi2SetReal(f.c, vrs, len(vrs), values)) > FMI2_WARNING:
                        f.fail("fmi2SetReal", status)
                t, h_k = (k * h, h) if self._clock is None else self._clock(k)
                for f in self.units.values():
                    f.t = t
                    if (status := f.dll.fmi2DoStep(f.c, t, h_k, 1)) > FMI2_WARNING:
                        f.fail("fmi2DoStep", status)
                k += 1
                for f, vrs, values in reads:
                    if (status := f.dll.fmi2GetReal(f.c, vrs, len(vrs), values)) > FMI2_WARNING:
                        f.fail("fmi2GetReal", status)
                s_inv += plant[inv]
        finally:
            self.k = k
        return self._record(n * h, s_inv / n, u_dc, w_m)

    def _record(self, duration: float, P_inv: float, u_dc: float, w_m: float) -> DriveStep:
        """The step's DriveStep: the means of the powers and torques from the plant's integrals,
        the inverter's loss (the mean of the plant's per inner step), the values at the end."""
        now = self._plant_integrals()
        P_elec, P_mech, P_cu, P_fe, T_e = ((b - a) / duration for a, b in zip(self._integrals[:5], now[:5]))
        self._integrals = now
        E_inv = now[5]
        controller = self.units["controller"]
        controller.read(*self._end)
        controller.read(*self._region, kind="Integer")
        i_d, i_q = (self.out["plant"][1][i] for i in self._i[:2])
        step = DriveStep(T_e - P_fe / w_m if w_m != 0.0 else T_e, T_e, (P_elec + P_inv) / u_dc, P_elec + P_inv,
                         P_mech, P_cu, P_fe, P_inv, P_elec, now[0] + E_inv, now[1], now[2], now[3], E_inv,
                         *self._end[1][:2], i_d, i_q, *self._end[1][2:], self._region[1][0])
        # the temperatures and heat flows at the end (the plant's; with the network off, the inputs
        # and zeros, as IpmsmDrive's) and the controller's derating, by name
        plant = self.units["plant"]
        if all(name in plant.vars for name in PLANT_THERMAL):
            for name, value in zip(PLANT_THERMAL, plant.get(*PLANT_THERMAL)):
                setattr(step, name, value)
            step.P_coolant, self._E_coolant = (step.E_coolant - self._E_coolant) / duration, step.E_coolant
        if "derating" in controller.vars:
            step.derating = controller.get("derating")
        if "P_loss_cmd" in controller.vars:  # the command's predicted loss (contract, "Least-loss control")
            step.P_loss_cmd = controller.get("P_loss_cmd")
        return step

    def close(self) -> None:
        for f in reversed(list(self.units.values())):
            f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
