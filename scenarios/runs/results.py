"""What a drive-cycle run produces (docs/spec/INTERFACE.md, "Scenario results"): the signals
of each vehicle step (`VehicleStep`), the trace sampled from them (`Trace`, trace.csv) and the
run's summary (`RunSummary`, summary.json). SI units; energies in Wh, as the contract names them.
"""
from __future__ import annotations

import csv
import math
import shutil
import tempfile
from dataclasses import asdict, astuple, dataclass, field, fields
from pathlib import Path

from scenarios.core.boundary import strict_json, write_atomically
from scenarios.core.version import VERSION
from scenarios.cosim.drive_fmu import DriveStep


@dataclass(slots=True)  # made at every vehicle step: a frozen dataclass's __init__ costs 3x
class VehicleStep:
    """The signals of one vehicle step (dt): the vehicle side's and the drive's, as the loop of
    scenarios.runs.simulate produces them. Speeds and SOC at the end of the step; w_m, u_dc, T_ref
    and F_brake held over it; powers and the currents I, I_opt are the step's."""

    t: float           # s, end of the step
    v_ref: float       # m/s, the cycle's speed at t
    v: float           # m/s, the vehicle's speed at t
    w_m: float         # rad/s, rotor speed (held)
    u_dc: float        # V, DC-link voltage the drive sees (held)
    T_ref: float       # N m, torque command of the brake blending (held)
    F_brake: float     # N, friction-brake force (held)
    drive: DriveStep   # the drive's outputs: means over the step, integrals, values at t
    P_inverter: float  # W, inverter loss
    P_dc: float        # W, DC-side power of the drive: P_elec + P_inverter
    I: float           # A, current magnitude, sqrt of the step's mean of i_d^2 + i_q^2
    I_opt: float       # A, the optimum's current at the delivered torque (NaN without the reference)
    P_cu_opt: float    # W, the optimum's copper loss (0 without the reference)
    soc: float         # battery state of charge at t
    F_demand: float = math.nan  # N, the driver's wheel-force demand, before the torque limit and blending
    F_wheel: float = math.nan   # N, the tractive force the drive delivered at the wheels
    fault: bool = False         # the drive's fault input over the step (a [fault] table; docs/faults.md)
    battery_limited: bool = False  # the battery's power limit took torque away (scenarios.runs.power_limit)
    P_loss_opt: float = math.nan  # W, the least-loss optimum's loss at the delivered shaft torque (NaN: none)
    distance: float = math.nan     # m, driven from the run's start to t


@dataclass(frozen=True)
class TracePoint:
    """One row of trace.csv; the field names are its columns."""

    time_s: float
    v_ref_mps: float
    v_mps: float
    w_m_rad_s: float
    T_ref_Nm: float
    T_cmd_Nm: float
    T_max_Nm: float
    T_e_Nm: float
    T_shaft_Nm: float
    i_d_A: float
    i_q_A: float
    I_A: float
    I_opt_A: float
    u_dc_V: float
    P_elec_W: float
    P_dc_W: float
    F_brake_N: float
    soc: float
    region: int
    P_demand_W: float        # the driver's demanded power at the wheels, F_demand v
    P_wheel_W: float         # the drive's delivered power at the wheels, F_wheel v
    theta_winding_K: float   # the thermal network's node temperatures (off: the run's inputs)
    theta_magnet_K: float
    theta_stator_yoke_K: float
    theta_stator_tooth_K: float
    P_coolant_W: float       # heat into the coolant (off: 0)
    derating: float          # the torque limit's thermal factor (1: none)
    P_cu_W: float            # the drive's losses, step means: copper, iron (plant), inverter
    P_fe_W: float
    P_inv_W: float
    P_loss_cmd_W: float      # the command's predicted loss P_cu + P_fe + P_inv (controller; NaN: an FMU without it)

    @classmethod
    def of(cls, s: VehicleStep) -> TracePoint:
        d = s.drive
        return cls(s.t, s.v_ref, s.v, s.w_m, s.T_ref, d.T_cmd, d.T_max, d.T_e, d.T_shaft, d.i_d, d.i_q, s.I, s.I_opt,
                   s.u_dc, d.P_elec, s.P_dc, s.F_brake, s.soc, int(d.region), s.F_demand * s.v, s.F_wheel * s.v,
                   d.theta_winding, d.theta_magnet, d.theta_stator_yoke, d.theta_stator_tooth, d.P_coolant,
                   d.derating, d.P_cu, d.P_fe, s.P_inverter, d.P_loss_cmd)


TRACE_COLUMNS = tuple(f.name for f in fields(TracePoint))


@dataclass
class Trace:
    """trace.csv: every `every`-th vehicle step (every = trace_dt / dt), streamed as CSV rows to
    an unlinked temporary file as the run goes (a long cycle needs bounded memory); `keep=False`
    (no output folder): nothing is kept."""

    every: int = 1
    keep: bool = True
    rows: int = 0
    _file: object = field(default=None, repr=False)
    _csv: object = field(default=None, repr=False)

    def observe(self, k: int, step: VehicleStep) -> None:
        """Vehicle step k (from 0) has ended."""
        if (k + 1) % self.every == 0 and self.keep:
            if self._file is None:
                self._file = tempfile.TemporaryFile("w+", newline="", encoding="utf-8")
                self._csv = csv.writer(self._file)
            self._csv.writerow(astuple(TracePoint.of(step)))
            self.rows += 1

    def write_csv(self, path: Path) -> None:
        """The header and the rows so far to `path`, atomically."""
        def write(tmp: Path) -> None:
            with open(tmp, "w", newline="", encoding="utf-8") as f:
                csv.writer(f).writerow(TRACE_COLUMNS)
                if self._file is not None:
                    self._file.flush()
                    self._file.seek(0)
                    shutil.copyfileobj(self._file, f)
                    self._file.seek(0, 2)
        write_atomically(path, write)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = self._csv = None


@dataclass(frozen=True)
class RunSummary:
    """summary.json: the contract's keys (cycle, method, distance_km, energy_battery_Wh, Wh_per_km,
    speed_rmse_mps, torque_rmse_Nm, torque_error_max_Nm, copper_loss_Wh, iron_loss_Wh, steps,
    wall_s) and the energy balance and accuracy figures around them, in this order; the loss
    split (E_cu, E_fe, E_inv: copper_loss_Wh, iron_loss_Wh, inverter_loss_Wh and their *_per_km)."""

    cycle: str
    method: str
    recursion: int
    conditions: dict                  # scenarios.runs.simulate.Conditions as a dict
    distance_km: float
    energy_battery_Wh: float          # at the battery's terminals
    Wh_per_km: float | None  # None when the run covered no distance
    speed_rmse_mps: float             # vehicle against the cycle, at the vehicle steps
    torque_rmse_Nm: float             # delivered (step mean of T_e; of T_shaft with least loss) against T_cmd
    torque_error_max_Nm: float
    torque_cmd_rms_Nm: float
    copper_loss_Wh: float
    copper_loss_optimal_Wh: float | None  # the exact optimum's at the delivered torque (None: no reference)
    time_above_V_max_pct: float       # voltage command above the planned V_max = k_u u_dc / sqrt 3
    time_voltage_limited_s: float     # ... at the inverter's linear range u_dc / sqrt 3
    time_voltage_limited_pct: float
    current_excess_rms_A: float       # |i| above the optimum's, RMS over the steps with |i| > 1 A
    iron_loss_Wh: float
    motor_electric_Wh: float
    shaft_Wh: float
    battery_internal_loss_Wh: float
    battery_energy_residual_Wh: float  # the battery's energy balance, zero up to rounding
    inverter_loss_Wh: float
    aux_Wh: float
    friction_brake_Wh: float
    regen_curtailed_Wh: float
    soc_end: float
    steps: int                        # co-simulation steps (h)
    vehicle_steps: int                # vehicle steps (dt)
    h_s: float
    dt_s: float
    wall_s: float
    real_time_factor: float
    backend: str                      # how the drive was simulated: drive (IpmsmDrive) or reference (reference loop)
    drive: str = ""                   # the drive description's name (scenarios.drives.description)
    drive_sha256: str = ""            # ... and the SHA-256 of its file: which drive, exactly
    w_m_peak_rpm: float = 0.0         # the highest rotor speed of the run
    w_m_max_rpm: float | None = None  # the motor's top speed (motor.w_m_max; None: not known)
    time_above_top_speed_s: float | None = 0.0  # time the rotor spent above w_m_max (None: w_m_max not known)
    version: str = VERSION            # the ipmsm-fmu release that ran it (pyproject.toml, the FMUs' version)
    # the machine's thermal network (docs/thermal.md); None with it off
    thermal_network: bool = False     # the thermal network was on ([thermal] thermal_model, or the conditions)
    theta_winding_max_K: float | None = None   # highest node temperatures of the run
    theta_magnet_max_K: float | None = None
    theta_stator_yoke_max_K: float | None = None
    theta_stator_tooth_max_K: float | None = None
    theta_winding_end_K: float | None = None
    theta_magnet_end_K: float | None = None
    heat_coolant_Wh: float | None = None       # heat into the coolant over the run
    heat_ambient_Wh: float | None = None       # ... into the ambient air
    heat_stored_Wh: float | None = None        # ... stored in the machine at the end
    heat_balance_residual_Wh: float | None = None  # copper + iron loss - stored - coolant - ambient
    # the controller's thermal derating of the torque limit, network on or off (it derates on the
    # temperatures it is given: the network's, or the run's inputs)
    time_derated_s: float | None = None        # time the torque limit was derated
    derating_min: float | None = None          # its lowest factor (1: none)
    # the inverter's fault (a [fault] table; docs/faults.md): the trigger and the policy, then
    # figures over the fault (None: no [fault] table, or no trip in the run)
    fault_trigger: str | None = None           # e.g. "fault.v_kmh = 130 km/h"
    fault_safe_state: str | None = None        # by_speed, freewheel or asc
    fault_time_s: float | None = None          # the communication point of the trip
    fault_speed_kmh: float | None = None       # the vehicle's speed there
    fault_speed_rpm: float | None = None       # the motor's
    fault_duration_s: float | None = None      # how long it lasted in the run
    fault_state: str | None = None             # the inverter state it entered: freewheel or asc
    fault_state_end: str | None = None         # ... and the one at its end (by_speed: freewheel -> asc past the onset)
    fault_i_peak_A: float | None = None        # largest current magnitude during the fault (the drive's i_peak)
    fault_i_d_demag_A: float | None = None     # the magnets' limit on i_d (the drive's i_d_demag)
    fault_demag_margin_A: float | None = None  # |i_d_demag| - fault_i_peak_A (|i_d| <= |i|: a safe bound)
    fault_T_peak_Nm: float | None = None       # largest braking shaft torque (10 ms means), a magnitude
    fault_charge_Ah: float | None = None       # charge into the DC link from the drive during the fault
    fault_energy_Wh: float | None = None       # ... energy
    fault_time_to_zero_current_s: float | None = None  # from the trip until |i| stays zero (None: it did not)
    # the DC link's energy balance: battery terminals - drive (P_elec + P_inverter) - auxiliaries
    # - curtailed regeneration (regen_curtailed_Wh, dissipated on the DC side), zero up to
    # rounding (a run where it would not close is an error, never a summary)
    dc_link_residual_Wh: float = 0.0
    time_battery_limited_s: float = 0.0        # time the battery's power limit held the torque back
    # the cycle as driven should have been (check's cycle-following limits, scenarios.runs.check)
    cycle_distance_km: float | None = None     # the trace's distance (trapezoidal, as Cycle.distance_m)
    cycle_moving_s: float | None = None        # the time the trace is not standing
    # least-loss control (docs/least_loss.md): what the controller minimised and the loss split
    objective: str = "current"                 # "current" (least current) or "loss" (least loss)
    controller_loss_scale: float = 1.0         # the controller's loss coefficients over the plant's
    copper_loss_Wh_per_km: float | None = None     # the loss split per km (None: no distance)
    iron_loss_Wh_per_km: float | None = None
    inverter_loss_Wh_per_km: float | None = None
    drive_loss_Wh: float = 0.0                 # copper + iron + inverter
    drive_loss_Wh_per_km: float | None = None
    drive_loss_cmd_Wh: float | None = None     # the commands' predicted loss (P_loss_cmd; None: an FMU without it)
    drive_loss_optimal_Wh: float | None = None  # the least-loss optimum's at the delivered shaft torque
    # ... and the same four figures up to the trip of a run whose fault came ([fault]; after the
    # trip the car has no traction by design, so check judges the cycle before it; None: no trip)
    speed_rmse_before_fault_mps: float | None = None     # over the vehicle steps before the trip (NaN: none)
    distance_before_fault_km: float | None = None        # driven until the trip
    cycle_distance_before_fault_km: float | None = None  # the trace's until the trip
    cycle_moving_before_fault_s: float | None = None     # the time the trace moves until the trip

    def to_dict(self) -> dict:
        return asdict(self)

    def to_json(self) -> str:
        """Strict JSON: a figure that is undefined (NaN, e.g. Wh_per_km of a run that stood still)
        is null, and `undefined` names those keys."""
        d = self.to_dict()
        d["undefined"] = [k for k, v in d.items() if v is None or (isinstance(v, float) and not math.isfinite(v))]
        return strict_json(d)


def write_results(out: Path, summary: RunSummary, trace: Trace) -> None:
    """summary.json and trace.csv in `out`."""
    out.mkdir(parents=True, exist_ok=True)
    write_atomically(out / "summary.json", summary.to_json())
    trace.write_csv(out / "trace.csv")
