"""One drive cycle with the FMUs: the vehicle side (driver, brake blending, vehicle, battery,
inverter losses) at dt = 10 ms around an opened drive, which returns the drive's step record
(DriveStep): the IpmsmDrive FMU (scenarios.cosim.drive_fmu) or the reference loop coupling
IpmsmController and IpmsmPlant at h = 100 us in Python (scenarios.cosim.reference), as
spec.backend names (open_drive). Results per the contract: summary.json and trace.csv
(scenarios.runs.results).

The loop (`vehicle_steps`) only simulates: it yields each vehicle step's signals, which the
accounts (scenarios.runs.accounting: energies, tracking errors) and the trace observe.

A reference controller (Ferrari, recursion 2, the exact optimum) is evaluated once per vehicle
step at the delivered torque and the same conditions, so every method's current and copper
loss can be compared with the optimum.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path

from scenarios.core.boundary import InputError
from scenarios.core.constants import T_REFERENCE_K, ZERO_CELSIUS_K
from scenarios.core.paths import BUILD_DIR, fmu_folder
from scenarios.core.progress import Progress
from scenarios.cosim import BACKENDS, backend_name
from scenarios.cosim.drive_fmu import DriveFmu
from scenarios.cosim.fmu import CosimError, Fmu
from scenarios.cosim.reference import ReferenceDrive
from scenarios.drives.description import METHODS, DriveDescription, ThermalSpec, controller_has_objective, load_drive
from scenarios.runs.accounting import DcLinkError, RunAccounts
from scenarios.runs.fault import FaultAccounts, FaultTrigger, demagnetisation_limit
from scenarios.runs.power_limit import advance_within
from scenarios.runs.results import RunSummary, Trace, VehicleStep, write_results
from scenarios.vehicle.battery import Battery
from scenarios.vehicle.cycles import Cycle, load_cycle, sampled, segment
from scenarios.vehicle.driver import BlendParams, Driver, DriverParams, blend
from scenarios.vehicle.longitudinal import Vehicle, motor_speed, wheel_force

__all__ = ["BACKENDS", "METHODS", "STUDY_CONDITIONS", "Conditions", "RunSpec", "fmu_paths", "simulate"]

#: the loss coefficients `controller_loss_scale` scales: the iron loss's (hysteresis, eddy
#: currents) and the inverter's (conduction: threshold voltages and slope resistances; switching
#: energies); not the exponents, reference points or the switching frequency, which say how a loss
#: scales, not how large it is
LOSS_COEFFICIENTS = ("fe_k_h", "fe_k_e", "V_T0", "r_T", "V_D0", "r_D", "E_on", "E_off", "E_rec")
#: the largest controller_loss_scale: a loss model off by more than a factor 10 is no estimate
CONTROLLER_LOSS_SCALE_MAX = 10.0

#: N m, the blending's torque limit before the controller has reported its reach (T_max, after
#: the first step): no limit
T_MAX_UNKNOWN = 1e9


@dataclass
class Conditions:
    """Operating conditions of a run. u_dc_scale: the DC voltage the drive sees, relative to the
    battery's terminal voltage (0.85: a pack sagging 15 % below what the tables were made for).
    The tables are always made at lut_u_dc and lut_T_magnet; None: the drive's (its
    controller.lut_u_dc and motor.T_magnet_ref), which the run's summary then records.
    thermal: the machine's thermal network on (True) or off (False), None: the drive's
    [thermal] thermal_model; with it on, T_magnet and T_winding are where the network starts."""

    name: str = "nominal"
    u_dc_scale: float = 1.0
    T_magnet: float = T_REFERENCE_K    # K
    T_winding: float = T_REFERENCE_K   # K
    lut_u_dc: float | None = None      # V
    lut_T_magnet: float | None = None  # K
    thermal: bool | None = None


STUDY_CONDITIONS = (
    Conditions("nominal"),
    Conditions("u_dc -15 %", u_dc_scale=0.85),
    Conditions("magnets 120 degC", T_magnet=120.0 + ZERO_CELSIUS_K, T_winding=120.0 + ZERO_CELSIUS_K),
    Conditions("magnets -20 degC", T_magnet=-20.0 + ZERO_CELSIUS_K, T_winding=-20.0 + ZERO_CELSIUS_K),
    # the seed's temperature argument as it happens: the machine's thermal network heats the
    # magnets and windings along the cycle from a cold start (the drive's coolant and ambient)
    Conditions("magnets heating from 20 degC", T_magnet=T_REFERENCE_K, T_winding=T_REFERENCE_K, thermal=True),
)


@dataclass
class RunSpec:
    """One run: the drive (motor, inverter, battery, vehicle, controller settings: a drive
    description, scenarios.drives.description), how it is driven and simulated. method and
    recursion None: the drive's [controller]."""

    drive: DriveDescription = field(default_factory=load_drive)
    method: str | None = None
    recursion: int | None = None
    command_check: int | None = None  # the controller's command check (None: the drive's)
    objective: str | None = None      # "current" or "loss" (None: the drive's controller.objective)
    #: the controller's loss coefficients (iron loss and inverter) over the plant's: 1.3 tells the
    #: controller 30 % more loss than the plant has (a drive's estimate that is off). Only the
    #: reference loop (backend "reference") has two sets; IpmsmDrive declares them once for both.
    controller_loss_scale: float = 1.0
    conditions: Conditions = field(default_factory=Conditions)
    dt: float = 0.01          # s, vehicle step
    h: float = 1e-4           # s, controller sample time = communication step
    trace_dt: float = 0.1     # s, trace.csv sampling
    backend: str = "drive"    # one of BACKENDS (or an alias, scenarios.cosim.BACKEND_ALIASES)
    reference: bool = True    # evaluate the exact optimum per vehicle step
    lut_grid: tuple[int, int] | None = None  # 2-D tables' points (torque, speed or V_max/w); None: the FMU's
    driver: DriverParams = field(default_factory=DriverParams)
    blend: BlendParams = field(default_factory=BlendParams)

    def __post_init__(self):
        self.backend = backend_name(self.backend)

    @property
    def method_name(self) -> str:
        return self.drive.controller.method if self.method is None else self.method

    @property
    def objective_name(self) -> str:
        return self.drive.controller.objective if self.objective is None else self.objective

    @property
    def recursion_level(self) -> int:
        return self.drive.controller.recursion if self.recursion is None else self.recursion

    def resolved_conditions(self) -> Conditions:
        """The conditions with the tables' lut_u_dc, lut_T_magnet filled in from the drive."""
        c, d = self.conditions, self.drive
        return replace(c, lut_u_dc=d.controller.lut_u_dc if c.lut_u_dc is None else c.lut_u_dc,
                       lut_T_magnet=d.motor.T_magnet_ref if c.lut_T_magnet is None else c.lut_T_magnet)

    def thermal(self) -> ThermalSpec:
        """The drive's [thermal] table with the conditions' thermal_model, if they set it."""
        t, on = self.drive.thermal, self.conditions.thermal
        return t if on is None or on == t.on else replace(t, values={**t.values, "thermal_model": on})

    def steps_per_vehicle_step(self) -> int:
        """Co-simulation steps h in one vehicle step dt (a whole number)."""
        n_inner = int(round(self.dt / self.h))
        if abs(n_inner * self.h - self.dt) > 1e-12 * self.dt:
            raise ValueError(f"the vehicle step {self.dt} s must be a whole number of controller steps {self.h} s")
        return n_inner


def fmu_paths(build: Path = BUILD_DIR, fmi: int = 2) -> tuple[Path, Path]:
    """The controller's and the plant's FMU of FMI version fmi (IpmsmDrive is beside them)."""
    folder = fmu_folder(build, fmi)
    return folder / "IpmsmController.fmu", folder / "IpmsmPlant.fmu"


def controller_loss_estimates(c_params: dict, spec: RunSpec) -> dict:
    """The controller's parameters with its loss coefficients (iron loss, inverter) scaled by
    spec.controller_loss_scale; only the reference loop can give the controller and the plant
    different ones."""
    scale = spec.controller_loss_scale
    if scale == 1.0:
        return c_params
    if not (math.isfinite(scale) and 0.0 < scale <= CONTROLLER_LOSS_SCALE_MAX):
        raise InputError("(command line)", "--controller-loss-scale",
                         f"a number in (0, {CONTROLLER_LOSS_SCALE_MAX:g}], got {scale!r}")
    if spec.backend != "reference":
        raise InputError("(command line)", "--controller-loss-scale", "the reference loop (--backend reference): "
                         "IpmsmDrive declares the loss parameters once for the controller and the plant")
    if "objective" not in c_params:
        raise InputError("(command line)", "--controller-loss-scale", "FMUs with the least-loss controller (the "
                         "`objective` parameter): rebuild them")
    return {**c_params, **{k: c_params[k] * scale for k in LOSS_COEFFICIENTS}}


def _open_drive_fmu(spec: RunSpec, controller_fmu: Path, plant_fmu: Path, c_params: dict, p_params: dict,
                    **start) -> DriveFmu:
    """IpmsmDrive (built next to the controller's FMU), with the thermal network's boundary."""
    thermal, fault = spec.thermal(), spec.drive.fault
    boundary = dict(T_coolant=thermal.T_coolant, T_ambient=thermal.T_ambient) if thermal.on else {}
    return DriveFmu(Path(controller_fmu).parent / "IpmsmDrive.fmu",
                    {**c_params, **p_params, **thermal.fmu_params(), "sample_time": spec.h,
                     **(fault.fmu_params() if fault is not None else {})}, **start, **boundary)


def _open_reference(spec: RunSpec, controller_fmu: Path, plant_fmu: Path, c_params: dict, p_params: dict,
                    **start) -> ReferenceDrive:
    """The reference loop. Not with the thermal network: the plant FMU alone advances it at every
    100 us step, IpmsmDrive once per communication step (docs/thermal.md), so the two would differ."""
    if spec.thermal().on:
        raise InputError("(command line)", "--backend", "the drive backend with the thermal network on "
                         "([thermal] thermal_model = true)")
    if spec.drive.fault is not None:  # the safe state's policy is IpmsmDrive's (contract, "Faults")
        raise InputError("(command line)", "--backend", "the drive backend with a [fault] table")
    return ReferenceDrive(controller_fmu, plant_fmu, c_params, p_params, h=spec.h, **start)


#: backend -> how a run opens its drive: the same parameters either way (the inverter's among the plant's)
OPEN_DRIVE = {"drive": _open_drive_fmu, "reference": _open_reference}


def open_drive(spec: RunSpec, controller_fmu: Path, plant_fmu: Path, c_params: dict, p_params: dict, **start):
    """The drive of a run, by spec.backend (OPEN_DRIVE)."""
    return OPEN_DRIVE[spec.backend](spec, controller_fmu, plant_fmu, c_params, p_params, **start)


#: rad/s, the reference optimum's current regulator: only the command is wanted (it does not
#: depend on the regulator), so the regulator is made slow enough that, stepped once per vehicle
#: step, nothing it integrates can grow
REFERENCE_CURRENT_BANDWIDTH = 1.0


class OptimumReference:
    """The exact optimum (the controller FMU with Ferrari, recursion 2, on the drive's motor) at a
    given torque and conditions: its current magnitude and copper loss at a winding resistance
    (the drive's R_s_T); and, with FMUs that have the least-loss controller,
    the least-loss optimum's predicted loss at a shaft torque (`least_loss`)."""

    def __init__(self, controller_fmu: Path, drive: DriveDescription, T_winding: float):
        self.T_winding = T_winding  # K: the optimum's voltage ellipse at the winding's resistance too
        self.loss_fmu = None
        self.fmu = Fmu(controller_fmu, instance_name="reference",
                       **{**drive.controller_params(method="ferrari", recursion=2, objective="current"),
                          "current_bandwidth": REFERENCE_CURRENT_BANDWIDTH})
        self.i_ref = (0.0, 0.0)  # A, the last command (d, q): the regulator's measured currents
        self.failed = ""         # why the optimum could not be evaluated (its figures then null)
        # The command is a function of the step's inputs alone; what the instance carries from
        # step to step (the regulator's) is no part of it. A step that fails on that carried state
        # is taken again from the instance as it was made (its clock restarted there).
        self._made, self._t0 = self.fmu.save_state(), 0.0
        try:
            if controller_has_objective():
                self.loss_fmu = LeastLossReference(controller_fmu, drive)
        except BaseException:
            self.close()
            raise

    def current(self, T_e: float, w_m: float, u_dc: float, T_magnet: float, t: float, dt: float,
                T_winding: float | None = None) -> float:
        """|i| (A) of the optimal command for T_e, one controller step at t; T_winding (K) None:
        the run's start (a run with the thermal network gives the step's)."""
        # The FMU's current regulator runs too, though only its command is wanted: its measured
        # currents are the command it gave (the current loop closed ideally), so the regulator
        # sees no error to integrate (left at 0 A it winds up until its voltage is not finite)
        inputs = dict(T_ref=T_e, w_m=w_m, u_dc=u_dc, T_magnet=T_magnet,
                      T_winding=self.T_winding if T_winding is None else T_winding)
        self.fmu.set(**inputs, i_d=self.i_ref[0], i_q=self.i_ref[1])
        try:
            self.fmu.step(t - self._t0, dt)
        except CosimError:  # the carried state's failure: once more from the instance as made
            self.fmu.restore_state(self._made)
            self._t0 = t
            self.fmu.set(**inputs)
            self.fmu.step(0.0, dt)
        self.i_ref = self.fmu.get("i_d_ref", "i_q_ref")
        return math.hypot(*self.i_ref)

    @staticmethod
    def copper_loss(I: float, R_s: float) -> float:
        """W at the current magnitude I (A, peak, amplitude-invariant dq) and the winding's
        resistance R_s (Ohm, the step's: the drive's R_s_T)."""
        return 1.5 * R_s * I * I

    def least_loss(self, T_shaft: float, w_m: float, u_dc: float, T_magnet: float, t: float, dt: float,
                   T_winding: float | None = None) -> float:
        """W, the least-loss optimum's loss (its P_loss_cmd) at the shaft torque T_shaft; NaN
        without the least-loss controller."""
        if self.loss_fmu is None:
            return math.nan
        return self.loss_fmu.loss(T_shaft, w_m, u_dc, T_magnet, self.T_winding if T_winding is None else T_winding,
                                  t, dt)

    def close(self) -> None:
        if self.fmu.fmu is not None:
            self.fmu.free_state(self._made)
        self.fmu.close()
        if self.loss_fmu is not None:
            self.loss_fmu.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class LeastLossReference(Fmu):
    """The least-loss optimum (the controller FMU with Ferrari, recursion 2, objective 1, on the
    drive's motor and loss models): its predicted loss P_loss_cmd at a shaft torque, one step per
    call through ctypes arrays made once (every vehicle step asks it)."""

    INPUTS = ("T_ref", "w_m", "u_dc", "T_magnet", "T_winding")

    def __init__(self, controller_fmu: Path, drive: DriveDescription):
        super().__init__(controller_fmu, instance_name="least_loss_reference",
                         **drive.controller_params(method="ferrari", recursion=2, objective="loss"))
        self._made = None
        try:
            self._u_vr, self._u = self.vrs(*self.INPUTS), (self.c_type("Real") * len(self.INPUTS))()
            self._y_vr, self._y = self.vrs("P_loss_cmd"), (self.c_type("Real") * 1)()
            # as OptimumReference's: a step that fails on the state carried from step to step (the
            # regulator's) is taken again from the instance as it was made, its clock restarted there
            self._made, self._t0 = self.save_state(), 0.0
        except BaseException:
            self.close()
            raise

    def loss(self, T_shaft: float, w_m: float, u_dc: float, T_magnet: float, T_winding: float, t: float,
             dt: float) -> float:
        self._u[:] = (T_shaft, w_m, u_dc, T_magnet, T_winding)
        self.write(self._u_vr, self._u)
        try:
            self.do_step(t - self._t0, dt)
        except CosimError:  # the carried state's failure: once more from the instance as made
            self.restore_state(self._made)
            self._t0 = t
            self.write(self._u_vr, self._u)
            self.do_step(0.0, dt)
        self.read(self._y_vr, self._y)
        return self._y[0]

    def close(self) -> None:
        if self.fmu is not None and getattr(self, "_made", None) is not None:
            self.free_state(self._made)
            self._made = None
        super().close()


def vehicle_steps(spec: RunSpec, t_ref: Sequence[float], v_ref: Sequence[float], drive: DriveFmu | ReferenceDrive,
                  vehicle: Vehicle, driver: Driver, battery: Battery,
                  reference: OptimumReference | None, fault: FaultTrigger | None = None) -> Iterator[VehicleStep]:
    """The vehicle-side loop (scenarios/driver.py describes one step) over the cycle sampled at
    t_ref (len(t_ref) - 1 steps of spec.dt) around `drive`; yields each step's signals once it
    has ended. `fault`: when the drive's fault input is on (scenarios.runs.fault)."""
    cond, vp, dt = spec.conditions, spec.drive.vehicle, spec.dt
    P_aux, I_max = spec.drive.P_aux, spec.drive.motor.I_max
    drive_dt = spec.steps_per_vehicle_step() * drive.sample_time
    # With the thermal network on, a step's copper loss is at the winding temperature the step
    # started at (the network advances at its end: the drive's R_s_T is the resistance there); the
    # reference optimum and the inputs follow the network's temperatures of the step before (inside
    # IpmsmDrive the controller takes the network's own; the inputs serve a drive without that feed).
    thermal = spec.thermal().on
    T_magnet, T_winding = cond.T_magnet, cond.T_winding
    T_max_known = T_MAX_UNKNOWN
    F_w = 0.0
    for k in range(len(t_ref) - 1):
        v = vehicle.v
        w_m = motor_speed(v, vp)
        u_dc = battery.u * cond.u_dc_scale
        on = fault is not None and fault.on(t_ref[k], v, w_m)
        if fault is not None:
            drive.set_fault(on)
        F_dem = driver.demand(v_ref[k], v_ref[k + 1], v, dt)
        if on:  # no traction torque; the friction brakes make up what the safe state's drag (the last step's) does not
            b = blend(F_dem - F_w, v, 0.0, 0.0, vp, spec.blend)
        else:
            b = blend(F_dem, v, T_max_known, battery.max_charge_power(dt) + P_aux, vp, spec.blend)
        # the DC link: the drive draws at most what the pack delivers (regeneration beyond what the
        # pack takes, which the blending's limit keeps rare, is curtailed: dissipated, and booked)
        lim = advance_within(drive, drive_dt, b.T_ref, w_m, u_dc, T_magnet, T_winding,
                             battery.max_discharge_power(dt) - P_aux, I_max, t_ref[k])
        m, T_ref, F_brake = lim.step, lim.T_ref, b.F_brake
        T_max_known = abs(m.T_max)
        F_w = wheel_force(m.T_shaft, vp)
        driver.applied(F_w - F_brake)
        vehicle.step(F_w, F_brake, dt)
        P_dc = m.P_elec + m.P_inv
        bs = battery.step(P_dc + P_aux, dt)
        if bs.P_unmet > 0.0:  # the limit above holds this; a broken one is an error, never energy from nothing
            raise DcLinkError(f"at t = {t_ref[k]:.6g} s the battery could not deliver the drive's {P_dc:.6g} W and "
                              f"the auxiliaries' {P_aux:.6g} W (short by {bs.P_unmet:.6g} W): the DC link's energy "
                              "balance would not close")
        R = m.R_s_T  # Ohm, the plant's over the step, its copper loss's: |i|^2 = P_cu / (1.5 R)
        if not R > 0.0:  # the plant's law keeps it positive at every temperature it accepts
            raise CosimError(f"the drive reports no stator resistance R_s_T > 0 (R_s_T = {R}): an FMU built "
                             "before that output; rebuild the FMUs")
        I = math.sqrt(max(m.P_cu / (1.5 * R), 0.0))
        I_opt, P_cu_opt, P_loss_opt = math.nan, 0.0, math.nan
        if reference is not None and not on and not reference.failed:
            try:
                I_opt = reference.current(m.T_e, w_m, u_dc, T_magnet, k * dt, dt, T_winding)
                P_cu_opt = reference.copper_loss(I_opt, R)
                P_loss_opt = reference.least_loss(m.T_shaft, w_m, u_dc, T_magnet, k * dt, dt, T_winding)
            except CosimError as e:  # a side computation: the run goes on, its optimum figures are null
                reference.failed = f"t = {k * dt:.6g} s: {e}"
                I_opt, P_cu_opt, P_loss_opt = math.nan, 0.0, math.nan
        yield VehicleStep(t=t_ref[k + 1], v_ref=v_ref[k + 1], v=vehicle.v, w_m=w_m, u_dc=u_dc, T_ref=T_ref,
                          F_brake=F_brake, drive=m, P_inverter=m.P_inv, P_dc=P_dc, I=I, I_opt=I_opt,
                          P_cu_opt=P_cu_opt, soc=battery.soc, F_demand=F_dem, F_wheel=F_w, fault=on,
                          battery_limited=lim.limited, P_loss_opt=P_loss_opt, distance=vehicle.distance)
        if thermal:
            T_magnet, T_winding = m.theta_magnet, m.theta_winding


def cycle_before(cycle: Cycle, t: float) -> dict:
    """The summary's cycle_distance_before_fault_km and cycle_moving_before_fault_s: the trace
    from its start to the trip at t (s, the cycle's time), as cycle_distance_km and cycle_moving_s."""
    t0, t1 = float(cycle.time_s[0]), float(cycle.time_s[-1])
    part = segment(cycle, t0, min(t, t1), rebase=False) if t > t0 else None  # a trip at the start: none
    return dict(cycle_distance_before_fault_km=0.0 if part is None else part.distance_m / 1000.0,
                cycle_moving_before_fault_s=0.0 if part is None else part.moving_s)


def simulate(cycle: Cycle | str, spec: RunSpec | None = None, fmus: tuple[Path, Path] | None = None,
             out: Path | None = None, progress: bool = True,
             observe: Callable[[VehicleStep], None] | None = None) -> RunSummary:
    """Run `cycle` with spec.drive on spec.backend's drive (open_drive); returns the summary (and
    writes summary.json, trace.csv to `out`). The FMUs' parameters (map, motor, controller
    settings, inverter) and the vehicle side all follow spec.drive; so does the reference optimum.
    `observe`, if given, sees every vehicle step (a test's independent account of the run)."""
    spec = spec if spec is not None else RunSpec()
    spec = replace(spec, conditions=spec.resolved_conditions())
    cycle = load_cycle(cycle) if isinstance(cycle, (str, Path)) else cycle
    controller_fmu, plant_fmu = fmus or fmu_paths()
    c_params = spec.drive.controller_params(spec.method_name, spec.recursion_level, spec.conditions.lut_u_dc,
                                            spec.conditions.lut_T_magnet, spec.command_check, spec.objective_name)
    c_params = controller_loss_estimates(c_params, spec)
    if spec.lut_grid is not None:
        c_params.update(lut_n_torque=spec.lut_grid[0], lut_n_speed=spec.lut_grid[1])
    # A segment may start at speed: so does the vehicle (and the motor, with a flying start).
    v0, cond = float(sampled(cycle, spec.dt, 1)[1][0]), spec.conditions
    start = dict(w_m=motor_speed(v0, spec.drive.vehicle), u_dc=Battery(spec.drive.battery).u * cond.u_dc_scale,
                 T_magnet=cond.T_magnet, T_winding=cond.T_winding)
    with open_drive(spec, controller_fmu, plant_fmu, c_params, spec.drive.plant_params(), **start) as drive:
        return drive_cycle(cycle, spec, drive, controller_fmu, out, progress, observe)


def drive_cycle(cycle: Cycle, spec: RunSpec, sim: DriveFmu | ReferenceDrive, controller_fmu: Path,
                out: Path | None = None, progress: bool = True,
                observe: Callable[[VehicleStep], None] | None = None) -> RunSummary:
    """simulate() on an opened drive `sim` (its conditions resolved, started as simulate starts
    it); controller_fmu: the reference optimum's FMU."""
    drive, method, recursion = spec.drive, spec.method_name, spec.recursion_level
    cond, vp, dt = spec.conditions, drive.vehicle, spec.dt
    n_inner = spec.steps_per_vehicle_step()
    n = int(round(cycle.duration_s / dt))
    t_ref, v_ref = sampled(cycle, dt, n)  # computed block by block: bounded memory for any length
    vehicle, driver = Vehicle(vp, v_ref[0]), Driver(vp, spec.driver)
    battery = Battery(drive.battery)
    accounts = RunAccounts(dt=dt, k_u=drive.controller.k_u, reference=spec.reference, w_m_max=drive.motor.w_m_max,
                           thermal=spec.thermal().on, shaft_torque_command=spec.objective_name == "loss")
    trace = Trace(every=max(1, int(round(spec.trace_dt / dt))), keep=out is not None)
    trigger = FaultTrigger(drive.fault) if drive.fault is not None else None
    faults = None
    bar = Progress(n, f"{cycle.name} {method} [{cond.name}]") if progress else None
    wall0 = time.perf_counter()
    try:
        with ExitStack() as stack:
            reference = (stack.enter_context(OptimumReference(controller_fmu, drive, cond.T_winding))
                         if spec.reference else None)
            if trigger is not None:
                faults = FaultAccounts(trigger, dt, drive.motor.I_max, demagnetisation_limit(sim))
            for k, step in enumerate(vehicle_steps(spec, t_ref, v_ref, sim, vehicle, driver, battery, reference,
                                                   trigger)):
                accounts.observe(step)
                if faults is not None:
                    faults.observe(step)
                trace.observe(k, step)
                if observe is not None:
                    observe(step)
                if bar:
                    bar.update()
    finally:
        if bar:
            bar.close()
    wall = time.perf_counter() - wall0
    summary = accounts.summary(cycle=cycle.name, method=method, recursion=recursion, conditions=cond,
                               vehicle=vehicle, battery=battery, P_aux=drive.P_aux, n=n, n_inner=n_inner, h=spec.h,
                               wall=wall, backend=spec.backend)
    summary = replace(summary, drive=drive.name, drive_sha256=drive.sha256, cycle_distance_km=cycle.distance_m / 1000.0,
                      cycle_moving_s=cycle.moving_s, objective=spec.objective_name,
                      controller_loss_scale=spec.controller_loss_scale,
                      **(faults.figures() if faults is not None else {}),
                      **(cycle_before(cycle, trigger.t_start) if trigger is not None and trigger.t_start is not None
                         else {}))
    try:
        if out is not None:
            write_results(out, summary, trace)
            if faults is not None:
                faults.write_csv(out / "fault_trace.csv")
    finally:
        trace.close()
    return summary
