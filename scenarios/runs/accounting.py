"""The run's accounts, kept step by step from the vehicle steps' signals: the drive's energies
(J), the tracking errors (sums of squares) and the time spent at the voltage limits (s).
`RunAccounts.summary` turns them, with the vehicle's and the battery's own bookkeeping, into the
RunSummary."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from scenarios.runs.results import RunSummary, VehicleStep

WH = 1 / 3600.0  # Wh per J

#: u_ratio above k_u by more than this counts as above the planned V_max (the regulator's
#: voltage is a sample, the plan a bound: a relative margin keeps rounding out of the count)
V_MAX_MARGIN = 1e-3

#: u_ratio at or above 1 within this counts as voltage-limited (the regulator's clamp)
U_LIMIT_TOLERANCE = 1e-9

#: A, below this the current excess is not counted (near zero torque its ratio means nothing)
I_EXCESS_MIN = 1.0

#: rotor speed above w_m_max by more than this (relative) counts as above the top speed (the
#: vehicle's speed is a state of an explicit step: rounding must not count)
TOP_SPEED_MARGIN = 1e-9

RPM = math.pi / 30.0  # rad/s per r/min

#: a derating factor below 1 by more than this counts as derated (the factor is a ratio of
#: temperatures: rounding must not count)
DERATING_MARGIN = 1e-9

#: the DC link's energy balance closes when its residual is within this fraction of the energy
#: through the link (each step's terms are one product apart: rounding leaves ~1e-15 per step)
DC_LINK_TOLERANCE = 1e-6


class DcLinkError(RuntimeError):
    """The DC link's energy balance (battery, drive, auxiliaries) does not close: the run's
    figures would be energy from nothing, so there are none."""


@dataclass
class RunAccounts:
    """Sums over the vehicle steps. k_u: the planned voltage reserve, V_max = k_u u_dc / sqrt 3;
    reference: the steps carry the optimum's current and copper loss."""

    dt: float
    k_u: float
    reference: bool
    w_m_max: float | None = None  # rad/s, the motor's top speed (None: not known, nothing flagged)
    #: the command's torque is the shaft's (least loss: contract, "Least-loss control"), else the
    #: air gap's: the torque error compares the delivered torque of the same kind
    shaft_torque_command: bool = False
    w_m_peak: float = 0.0     # rad/s, the highest rotor speed
    t_above_top: float = 0.0  # s above w_m_max
    E_elec: float = 0.0       # J, motor electric input
    E_mech: float = 0.0       # J, shaft
    E_cu: float = 0.0         # J, copper loss
    E_fe: float = 0.0         # J, iron loss
    E_inv: float = 0.0        # J, inverter loss
    E_cu_opt: float = 0.0     # J, the optimum's copper loss
    E_loss_cmd: float = 0.0   # J, the commands' predicted loss (P_loss_cmd; NaN: an FMU without it)
    E_loss_opt: float = 0.0   # J, the least-loss optimum's loss (NaN: no such optimum)
    T_err2: float = 0.0       # N^2 m^2, sum of (T_e - T_cmd)^2
    T_err_max: float = 0.0    # N m
    T_cmd2: float = 0.0       # N^2 m^2, sum of T_cmd^2
    n_T: int = 0
    speed_err2: float = 0.0   # m^2/s^2, sum of (v - v_ref)^2
    I_excess2: float = 0.0    # A^2, sum of (I - I_opt)^2 where I > I_EXCESS_MIN
    n_I: int = 0
    t_over: float = 0.0       # s above the planned V_max
    t_sat: float = 0.0        # s at the inverter's linear range
    thermal: bool = False     # the thermal network is on: its figures are kept
    theta_max: tuple = (-math.inf,) * 4  # K, winding, magnet, stator yoke, stator tooth
    t_derated: float = 0.0    # s with the torque limit derated
    derating_min: float = 1.0
    last: object = None       # the last step's drive record (the run's end)
    E_dc: float = 0.0         # J, the drive's DC side: P_elec + P_inverter
    E_dc_abs: float = 0.0     # J, the energy through the DC link (|drive| + auxiliaries)
    t_battery_limited: float = 0.0  # s with the battery's power limit holding the torque back
    reference_lost: bool = False    # a step without the optimum: its figures are null
    n_steps: int = 0          # vehicle steps observed
    distance: float = 0.0     # m, driven by the end of the last one
    before_fault: tuple | None = None  # (speed_err2, n_steps, distance) at the fault's trip (None: no trip)

    def observe(self, s: VehicleStep) -> None:
        """One vehicle step has ended."""
        dt, m = self.dt, s.drive  # means over the step; T_cmd, u_ratio at its end
        if s.fault and self.before_fault is None:  # the trip: the run so far is the part check judges
            self.before_fault = (self.speed_err2, self.n_steps, self.distance)
        self.n_steps += 1
        self.distance = s.distance
        # Voltage use, sampled at the vehicle step: above the planned V_max = k_u u_dc / sqrt 3
        # (the optimum's reserve for the regulator), and at the inverter's limit u_dc / sqrt 3.
        if m.u_ratio > self.k_u * (1.0 + V_MAX_MARGIN):
            self.t_over += dt
        if m.u_ratio >= 1.0 - U_LIMIT_TOLERANCE:
            self.t_sat += dt
        self.E_elec += m.P_elec * dt
        self.E_mech += m.P_mech * dt
        self.E_cu += m.P_cu * dt
        self.E_fe += m.P_fe * dt
        self.E_inv += s.P_inverter * dt
        self.E_dc += s.P_dc * dt
        self.E_dc_abs += abs(s.P_dc) * dt
        if s.battery_limited:
            self.t_battery_limited += dt
        self.E_loss_cmd += m.P_loss_cmd * dt
        # Torque error: delivered (mean T_e, or T_shaft for a shaft-torque command) against the
        # command within reach (none in a fault: the inverter does not switch, nothing is
        # controlled; scenarios.runs.fault)
        if not s.fault:
            T_err = (m.T_shaft if self.shaft_torque_command else m.T_e) - m.T_cmd
            self.T_err2 += T_err * T_err
            self.T_cmd2 += m.T_cmd * m.T_cmd
            self.T_err_max = max(self.T_err_max, abs(T_err))
            self.n_T += 1
        self.speed_err2 += (s.v - s.v_ref) ** 2
        self.w_m_peak = max(self.w_m_peak, abs(s.w_m))
        if self.w_m_max is not None and abs(s.w_m) > self.w_m_max * (1.0 + TOP_SPEED_MARGIN):
            self.t_above_top += dt
        # the controller derates on the temperatures it is given, the network's or the inputs
        if m.derating < 1.0 - DERATING_MARGIN:
            self.t_derated += dt
        self.derating_min = min(self.derating_min, m.derating)
        if self.thermal:
            self.theta_max = tuple(max(a, b) for a, b in zip(self.theta_max, (
                m.theta_winding, m.theta_magnet, m.theta_stator_yoke, m.theta_stator_tooth)))
            self.last = m
        if self.reference:
            if math.isnan(s.I_opt):  # the optimum could not be evaluated: its figures are unknown
                self.reference_lost = True
            self.E_cu_opt += s.P_cu_opt * dt
            self.E_loss_opt += s.P_loss_opt * dt
            if s.I > I_EXCESS_MIN and not s.fault:
                self.I_excess2 += (s.I - s.I_opt) ** 2
                self.n_I += 1

    def summary(self, *, cycle: str, method: str, recursion: int, conditions, vehicle, battery, P_aux: float,
                n: int, n_inner: int, h: float, wall: float, backend: str) -> RunSummary:
        """The summary of n vehicle steps of n_inner co-simulation steps h each. vehicle, battery:
        scenarios.vehicle.longitudinal.Vehicle and scenarios.vehicle.battery.Battery after the run."""
        dt = self.dt
        km = vehicle.distance / 1000.0
        E_aux = P_aux * n * dt
        # regeneration the pack refused (the blending keeps it rare) is dissipated on the DC side
        dc_residual = battery.E_terminal - self.E_dc - E_aux - battery.E_curtailed
        if not abs(dc_residual) <= DC_LINK_TOLERANCE * max(self.E_dc_abs + E_aux, 1.0):
            raise DcLinkError(f"the DC link's energy balance does not close: the battery's terminals gave "
                              f"{battery.E_terminal * WH:.9g} Wh, the drive took {self.E_dc * WH:.9g} Wh, the "
                              f"auxiliaries {E_aux * WH:.9g} Wh, curtailed regeneration {battery.E_curtailed * WH:.9g} "
                              f"Wh (residual {dc_residual * WH:.3g} Wh)")
        n_T = max(self.n_T, 1)
        return RunSummary(
            cycle=cycle, method=method, recursion=recursion, conditions=asdict(conditions),
            distance_km=km, energy_battery_Wh=battery.E_terminal * WH,
            Wh_per_km=battery.E_terminal * WH / km if km > 0.0 else None,  # none: the car stood still
            speed_rmse_mps=math.sqrt(self.speed_err2 / n),
            torque_rmse_Nm=math.sqrt(self.T_err2 / n_T), torque_error_max_Nm=self.T_err_max,
            torque_cmd_rms_Nm=math.sqrt(self.T_cmd2 / n_T),
            copper_loss_Wh=self.E_cu * WH,
            copper_loss_optimal_Wh=self.E_cu_opt * WH if self.reference and not self.reference_lost else None,
            time_above_V_max_pct=100.0 * self.t_over / (n * dt), time_voltage_limited_s=self.t_sat,
            time_voltage_limited_pct=100.0 * self.t_sat / (n * dt),
            current_excess_rms_A=(math.nan if self.reference_lost else
                                  math.sqrt(self.I_excess2 / self.n_I) if self.n_I else 0.0),
            iron_loss_Wh=self.E_fe * WH, motor_electric_Wh=self.E_elec * WH, shaft_Wh=self.E_mech * WH,
            battery_internal_loss_Wh=(battery.E_loss_R0 + battery.E_loss_R1) * WH,
            battery_energy_residual_Wh=battery.energy_residual() * WH, inverter_loss_Wh=self.E_inv * WH,
            aux_Wh=E_aux * WH, friction_brake_Wh=vehicle.E_brake * WH,
            regen_curtailed_Wh=battery.E_curtailed * WH, soc_end=battery.soc,
            steps=n * n_inner, vehicle_steps=n, h_s=h, dt_s=dt, wall_s=wall, real_time_factor=n * dt / wall,
            backend=backend, w_m_peak_rpm=self.w_m_peak / RPM,
            w_m_max_rpm=None if self.w_m_max is None else self.w_m_max / RPM,
            time_above_top_speed_s=None if self.w_m_max is None else self.t_above_top,
            time_derated_s=self.t_derated, derating_min=self.derating_min, dc_link_residual_Wh=dc_residual * WH,
            time_battery_limited_s=self.t_battery_limited, **self.thermal_figures(), **self.loss_split(km),
            **self.before_fault_figures(),
        )

    def loss_split(self, km: float) -> dict:
        """The drive's losses (E_cu, E_fe, E_inv) in Wh and per km, their sum, the commands'
        predicted loss and the least-loss optimum's (None where the FMUs have none)."""
        E = self.E_cu + self.E_fe + self.E_inv
        def per_km(J):
            return J * WH / km if km > 0.0 else None
        def known(J):
            return J * WH if math.isfinite(J) else None
        return dict(copper_loss_Wh_per_km=per_km(self.E_cu), iron_loss_Wh_per_km=per_km(self.E_fe),
                    inverter_loss_Wh_per_km=per_km(self.E_inv), drive_loss_Wh=E * WH, drive_loss_Wh_per_km=per_km(E),
                    drive_loss_cmd_Wh=known(self.E_loss_cmd),
                    drive_loss_optimal_Wh=known(self.E_loss_opt) if self.reference else None)

    def before_fault_figures(self) -> dict:
        """The summary's speed error and distance up to the fault's trip (none: no trip; no step
        before it, a trip at the start: the speed error is undefined, NaN)."""
        if self.before_fault is None:
            return {}
        err2, n, x = self.before_fault
        return dict(speed_rmse_before_fault_mps=math.sqrt(err2 / n) if n else math.nan,
                    distance_before_fault_km=x / 1000.0)

    def thermal_figures(self) -> dict:
        """The summary's thermal figures (none with the network off)."""
        m = self.last
        if not self.thermal or m is None:
            return {}
        return dict(
            thermal_network=True, theta_winding_max_K=self.theta_max[0], theta_magnet_max_K=self.theta_max[1],
            theta_stator_yoke_max_K=self.theta_max[2], theta_stator_tooth_max_K=self.theta_max[3],
            theta_winding_end_K=m.theta_winding, theta_magnet_end_K=m.theta_magnet,
            heat_coolant_Wh=m.E_coolant * WH, heat_ambient_Wh=m.E_ambient * WH, heat_stored_Wh=m.E_stored * WH,
            heat_balance_residual_Wh=(m.E_cu + m.E_fe - m.E_stored - m.E_coolant - m.E_ambient) * WH)
