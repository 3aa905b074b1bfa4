"""A fault in a drive-cycle run (a drive description's [fault] table; docs/faults.md): when the
inverter stops switching (`FaultTrigger`), and what it did (`FaultAccounts`: the summary's
`fault_*` figures and fault_trace.csv, every vehicle step around the trip).

The fault goes in through IpmsmDrive's `fault` input at a communication point (the start of a
vehicle step); the drive enters its safe state (contract, "Faults"). While it lasts the driver
can get no traction torque: the brake blending sees no motor reach, and the friction brakes make
up what the driver asks beyond the drag the safe state already gives (the last step's).
"""
from __future__ import annotations

import csv
import math
from collections import deque
from dataclasses import astuple, dataclass, field
from pathlib import Path

from scenarios.core.boundary import write_atomically
from scenarios.drives.description import FaultSpec

RPM = math.pi / 30.0  # rad/s per r/min
KMH = 1 / 3.6         # m/s per km/h
WH, AH = 1 / 3600.0, 1 / 3600.0  # Wh per J, Ah per A s

#: s, a time trigger within this of a communication point fires there (the points are sums of
#: the vehicle step: rounding must not move the fault by a whole step)
TIME_TOLERANCE = 1e-9

#: the current counts as zero below this share of the motor's current limit I_max: the accuracy
#: class of the Hall-effect phase-current transducers of traction inverters (1 % of their range,
#: which is of the order of I_max)
ZERO_CURRENT_FRACTION = 0.01

#: fault_trace.csv: every vehicle step from this long before the trip ...
TRACE_BEFORE_S = 1.0
#: ... to this long after the fault ended, and at most this long after the trip (bounded rows)
TRACE_AFTER_END_S = 2.0
TRACE_AFTER_MAX_S = 120.0

#: IpmsmDrive's `inverter_state` values by name (contract, "Faults")
INVERTER_STATES = {0: "switching", 1: "freewheel", 2: "asc"}


def demagnetisation_limit(unit) -> float | None:
    """A (< 0), the drive's i_d_demag; None where it has none (0, the FMU's default, or no such
    parameter)."""
    if "i_d_demag" not in unit.vars:
        return None
    x = float(unit.get("i_d_demag"))
    return x if x < 0.0 else None


class FaultTrigger:
    """When the fault is on: from the first communication point at which the trigger is reached
    (a time at or after `t_s`, a motor speed at or above `speed_rpm`, a vehicle speed at or above
    `v_kmh`: a run that starts beyond it trips at once) for duration_s (None: to the end). One
    fault per run."""

    def __init__(self, spec: FaultSpec):
        self.spec = spec
        self.t_start: float | None = None   # s, the communication point of the trip
        self.v_start = math.nan             # m/s, the vehicle's speed there
        self.w_m_start = math.nan           # rad/s, the motor's

    def reached(self, t: float, v: float, w_m: float) -> bool:
        at = self.spec.at
        return {"t_s": t >= at - TIME_TOLERANCE, "speed_rpm": abs(w_m) >= at * RPM,
                "v_kmh": v >= at * KMH}[self.spec.trigger]

    def on(self, t: float, v: float, w_m: float) -> bool:
        """The fault input over the vehicle step that starts at t with speeds v, w_m."""
        if self.t_start is None:
            if not self.reached(t, v, w_m):
                return False
            self.t_start, self.v_start, self.w_m_start = t, v, w_m
            return True
        d = self.spec.duration_s
        return d is None or t < self.t_start + d - TIME_TOLERANCE


@dataclass(frozen=True)
class FaultRow:
    """One row of fault_trace.csv (a vehicle step, values at its end unless said: means)."""

    time_s: float
    fault: int                 # the fault input over the step (1: on)
    inverter_state: int        # 0 switching, 1 freewheeling, 2 ASC
    v_kmh: float
    w_m_rpm: float
    T_e_Nm: float              # mean
    T_shaft_Nm: float          # mean
    i_d_A: float
    i_q_A: float
    I_A: float                 # |i| at the step's end
    i_peak_A: float            # largest |i| since the fault began (IpmsmDrive's i_peak)
    i_dc_A: float              # DC-link current of the drive, mean (< 0: into the battery)
    P_dc_W: float              # mean
    u_dc_V: float
    F_brake_N: float
    theta_winding_K: float
    theta_magnet_K: float


FAULT_TRACE_COLUMNS = tuple(f.name for f in FaultRow.__dataclass_fields__.values())


@dataclass
class FaultAccounts:
    """The fault's figures, kept from the vehicle steps (scenarios.runs.results.VehicleStep with
    its `fault` flag): I_max (A) sets what counts as zero current; i_d_demag (A) is the drive's."""

    trigger: FaultTrigger
    dt: float
    I_max: float
    i_d_demag: float | None = None
    t_end: float | None = None        # s, the end of the last step with the fault on
    i_peak: float = 0.0               # A
    T_brake_peak: float = 0.0         # N m, the largest braking (negative) mean shaft torque, as a magnitude
    charge: float = 0.0               # A s into the DC link from the drive
    energy: float = 0.0               # J into the DC link from the drive
    t_last_current: float | None = None  # s, end of the last fault step with a current above zero
    current_at_end: float = math.nan  # A, |i| at the end of the fault
    states: list = field(default_factory=list)  # inverter states entered, in order
    rows: deque = field(default_factory=lambda: deque(maxlen=1))
    rows_after: int = 0

    def __post_init__(self):
        self.rows = deque(maxlen=max(1, int(round(TRACE_BEFORE_S / self.dt))))
        self.trace: list[FaultRow] = []

    def observe(self, s) -> None:
        m = s.drive
        row = FaultRow(s.t, int(s.fault), int(m.inverter_state), s.v / KMH, s.w_m / RPM, m.T_e, m.T_shaft, m.i_d,
                       m.i_q, math.hypot(m.i_d, m.i_q), m.i_peak, m.i_dc, m.P_dc, s.u_dc, s.F_brake, m.theta_winding,
                       m.theta_magnet)
        self._keep(row)
        if not s.fault:
            return
        self.t_end = s.t
        self.i_peak = max(self.i_peak, m.i_peak, row.I_A)
        self.T_brake_peak = max(self.T_brake_peak, -m.T_shaft)
        self.charge -= m.i_dc * self.dt
        self.energy -= m.P_dc * self.dt
        if row.I_A > ZERO_CURRENT_FRACTION * self.I_max:
            self.t_last_current = s.t
        self.current_at_end = row.I_A
        name = INVERTER_STATES.get(row.inverter_state, str(row.inverter_state))
        if not self.states or self.states[-1] != name:
            self.states.append(name)

    def _keep(self, row: FaultRow) -> None:
        t0 = self.trigger.t_start
        if t0 is None:
            self.rows.append(row)     # the last TRACE_BEFORE_S before a trip that may come
            return
        if not self.trace and self.rows:
            self.trace.extend(self.rows)
            self.rows.clear()
        end = row.time_s - t0 > TRACE_AFTER_MAX_S or (
            self.t_end is not None and not row.fault and row.time_s - self.t_end > TRACE_AFTER_END_S)
        if not end:
            self.trace.append(row)

    def figures(self) -> dict:
        """The summary's fault_* keys (scenarios.runs.results.RunSummary); None where not
        applicable (no trip in the run: every figure)."""
        tr, spec = self.trigger, self.trigger.spec
        out = dict(fault_trigger=spec.describe(), fault_safe_state=spec.safe_state)
        if tr.t_start is None:
            return out
        zero = self.current_at_end <= ZERO_CURRENT_FRACTION * self.I_max
        margin = None if self.i_d_demag is None else abs(self.i_d_demag) - self.i_peak
        return dict(
            out, fault_time_s=tr.t_start, fault_speed_kmh=tr.v_start / KMH, fault_speed_rpm=tr.w_m_start / RPM,
            fault_duration_s=self.t_end - tr.t_start, fault_state=self.states[0] if self.states else None,
            fault_state_end=self.states[-1] if self.states else None, fault_i_peak_A=self.i_peak,
            fault_i_d_demag_A=self.i_d_demag, fault_demag_margin_A=margin, fault_T_peak_Nm=self.T_brake_peak,
            fault_charge_Ah=self.charge * AH, fault_energy_Wh=self.energy * WH,
            fault_time_to_zero_current_s=None if not zero else (
                0.0 if self.t_last_current is None else self.t_last_current - tr.t_start))

    def write_csv(self, path: Path) -> None:
        """fault_trace.csv (only the header when the fault never came)."""
        def write(tmp: Path) -> None:
            with open(tmp, "w", newline="", encoding="utf-8") as f:
                w = csv.writer(f)
                w.writerow(FAULT_TRACE_COLUMNS)
                w.writerows(astuple(r) for r in self.trace)
        write_atomically(path, write)
