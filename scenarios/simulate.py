"""One drive cycle with the FMUs: the vehicle side (driver, brake blending, vehicle, battery,
inverter losses) at dt = 10 ms around the co-simulated drive (IpmsmController + IpmsmPlant at
h = 100 us, scenarios.master). Results per the contract: summary.json and trace.csv.

A reference controller (Ferrari, recursion 2, the exact optimum) is evaluated once per vehicle
step at the delivered torque and the same conditions, so every method's current and copper
loss can be compared with the optimum.
"""
from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .battery import Battery, BatteryParams
from .cycles import Cycle, load_cycle
from .driver import P_AUX_DEFAULT, BlendParams, Driver, DriverParams, blend
from .flux_map import DEFAULT_MAP, MotorData, read_flux_map
from .fmu import Fmu
from .inverter import InverterParams, inverter_loss
from .drive_fmu import DriveAsCosim
from .master import DriveCosim
from .progress import Progress
from .vehicle import Vehicle, VehicleParams, motor_speed, wheel_force

ROOT = Path(__file__).resolve().parents[1]
CELSIUS = 273.15  # K at 0 degC

#: the contract's method names and the controller's `method` parameter
METHODS = {"ferrari": 1, "lut_speed": 2, "lut_flux": 3}


@dataclass
class Conditions:
    """Operating conditions of a run. u_dc_scale: the DC voltage the drive sees, relative to the
    battery's terminal voltage (0.85: a pack sagging 15 % below what the tables were made for).
    The tables are always made at lut_u_dc and lut_T_magnet."""

    name: str = "nominal"
    u_dc_scale: float = 1.0
    T_magnet: float = 20.0 + CELSIUS   # K
    T_winding: float = 20.0 + CELSIUS  # K
    lut_u_dc: float = 355.0            # V, the pack's nominal (the default motor's design point)
    lut_T_magnet: float = 20.0 + CELSIUS


STUDY_CONDITIONS = (
    Conditions("nominal"),
    Conditions("u_dc -15 %", u_dc_scale=0.85),
    Conditions("magnets 120 degC", T_magnet=120.0 + CELSIUS, T_winding=120.0 + CELSIUS),
    Conditions("magnets -20 degC", T_magnet=-20.0 + CELSIUS, T_winding=-20.0 + CELSIUS),
)


@dataclass
class RunSpec:
    method: str = "ferrari"
    recursion: int = 2
    conditions: Conditions = field(default_factory=Conditions)
    dt: float = 0.01          # s, vehicle step
    h: float = 1e-4           # s, controller sample time = communication step
    trace_dt: float = 0.1     # s, trace.csv sampling
    backend: str = "auto"     # master: native if built, else fmpy; "drive": the IpmsmDrive FMU
    reference: bool = True    # evaluate the exact optimum per vehicle step
    P_aux: float = P_AUX_DEFAULT
    soc0: float | None = None
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    driver: DriverParams = field(default_factory=DriverParams)
    battery: BatteryParams = field(default_factory=BatteryParams)
    inverter: InverterParams = field(default_factory=InverterParams)
    blend: BlendParams = field(default_factory=BlendParams)


def fmu_paths(build: Path = ROOT / "build") -> tuple[Path, Path]:
    return build / "fmu" / "IpmsmController.fmu", build / "fmu" / "IpmsmPlant.fmu"


TRACE_COLUMNS = ("time_s", "v_ref_mps", "v_mps", "w_m_rad_s", "T_ref_Nm", "T_cmd_Nm", "T_max_Nm", "T_e_Nm",
                 "T_shaft_Nm", "i_d_A", "i_q_A", "I_A", "I_opt_A", "u_dc_V", "P_elec_W", "P_dc_W",
                 "F_brake_N", "soc", "region")


def simulate(cycle: Cycle | str, spec: RunSpec = RunSpec(), fmus: tuple[Path, Path] | None = None,
             out: Path | None = None, progress: bool = True) -> dict:
    """Run `cycle`; returns the summary (and writes summary.json, trace.csv to `out`)."""
    cycle = load_cycle(cycle) if isinstance(cycle, (str, Path)) else cycle
    controller_fmu, plant_fmu = fmus or fmu_paths()
    cond, vp, dt = spec.conditions, spec.vehicle, spec.dt
    n_inner = int(round(dt / spec.h))
    if abs(n_inner * spec.h - dt) > 1e-12 * dt:
        raise ValueError(f"the vehicle step {dt} s must be a whole number of controller steps {spec.h} s")
    if spec.method not in METHODS:
        raise ValueError(f"method {spec.method!r}: one of {', '.join(METHODS)}")
    c_params = dict(method=METHODS[spec.method], recursion=spec.recursion,
                    lut_u_dc=cond.lut_u_dc, lut_T_magnet=cond.lut_T_magnet)
    n = int(round(cycle.duration_s / dt))
    t_ref = cycle.time_s[0] + dt * np.arange(n + 1)
    v_ref = cycle.speed_at(t_ref).tolist()
    # A segment may start at speed: so does the vehicle (and the motor, with a flying start).
    motor = MotorData.of(read_flux_map(DEFAULT_MAP))  # the FMUs' defaults: the reference's R_s, k_u
    veh, drv, bat = Vehicle(vp, v_ref[0]), Driver(vp, spec.driver), Battery(spec.battery, spec.soc0)
    every = max(1, int(round(spec.trace_dt / dt)))

    acc = dict(E_elec=0.0, E_mech=0.0, E_cu=0.0, E_fe=0.0, E_inv=0.0, E_cu_opt=0.0, T_err2=0.0, T_err_max=0.0, n_T=0, T_cmd2=0.0, t_over=0.0,
               I_excess2=0.0, n_I=0, t_sat=0.0, speed_err2=0.0)
    rows = []
    T_max_known = 1e9  # the controller reports its reach after the first step
    bar = Progress(n, f"{cycle.name} {spec.method} [{cond.name}]") if progress else None
    wall0 = time.perf_counter()
    ref = Fmu(controller_fmu, instance_name="reference", method=1, recursion=2) if spec.reference else None
    start = dict(w_m=motor_speed(veh.v, vp), u_dc=bat.u * cond.u_dc_scale, T_magnet=cond.T_magnet,
                 T_winding=cond.T_winding)
    if spec.backend == "drive":  # the IpmsmDrive FMU (next to the controller's), with its inverter loss
        drive = DriveAsCosim(Path(controller_fmu).parent / "IpmsmDrive.fmu", c_params, {}, h=spec.h,
                             inverter_params=asdict(spec.inverter), **start)
    try:
        with (drive if spec.backend == "drive" else
              DriveCosim(controller_fmu, plant_fmu, c_params, {}, h=spec.h, backend=spec.backend, **start)) as cosim:
            for k in range(n):
                v = veh.v
                w_m = motor_speed(v, vp)
                u_dc = bat.u * cond.u_dc_scale
                F_dem = drv.demand(v_ref[k], v_ref[k + 1], v, dt)
                b = blend(F_dem, v, T_max_known, bat.max_charge_power(dt) + spec.P_aux, vp, spec.blend)
                r = cosim.advance(n_inner, T_ref=b.T_ref, w_m=w_m, u_dc=u_dc, T_magnet=cond.T_magnet,
                                  T_winding=cond.T_winding)
                m, e = r.mean, r.end
                T_max_known = abs(e.T_max)
                # Voltage use, sampled at the vehicle step: above the planned V_max = k_u u_dc / sqrt 3
                # (the optimum's reserve for the regulator), and at the inverter's limit u_dc / sqrt 3.
                if e.u_ratio > motor.k_u * (1.0 + 1e-3):
                    acc["t_over"] += dt
                if e.u_ratio >= 1.0 - 1e-9:
                    acc["t_sat"] += dt
                F_w = wheel_force(m.T_shaft, vp)
                drv.applied(F_w - b.F_brake)
                veh.step(F_w, b.F_brake, dt)
                P_inv = (r.P_inverter if spec.backend == "drive" else
                         inverter_loss(m.i_abs, m.i_abs_sq, u_dc, P_ac_mean=m.P_elec, p=spec.inverter).P)
                P_dc = m.P_elec + P_inv
                bat.step(P_dc + spec.P_aux, dt)

                acc["E_elec"] += m.P_elec * dt
                acc["E_mech"] += m.P_mech * dt
                acc["E_cu"] += m.P_cu * dt
                acc["E_fe"] += m.P_fe * dt
                acc["E_inv"] += P_inv * dt
                # Torque error: delivered (mean T_e) against the command within reach.
                T_err = m.T_e - m.T_cmd
                acc["T_err2"] += T_err * T_err
                acc["T_cmd2"] += m.T_cmd * m.T_cmd
                acc["T_err_max"] = max(acc["T_err_max"], abs(T_err))
                acc["n_T"] += 1
                acc["speed_err2"] += (veh.v - v_ref[k + 1]) ** 2
                I = math.sqrt(max(m.i_abs_sq, 0.0))
                I_opt = float("nan")
                if ref is not None:
                    ref.set(T_ref=m.T_e, w_m=w_m, u_dc=u_dc, T_magnet=cond.T_magnet)
                    ref.step(k * dt, dt)
                    I_opt = math.hypot(*ref.get("i_d_ref", "i_q_ref"))
                    acc["E_cu_opt"] += 1.5 * motor.R_s_at(cond.T_winding) * I_opt * I_opt * dt
                    if I > 1.0:
                        acc["I_excess2"] += (I - I_opt) ** 2
                        acc["n_I"] += 1
                if (k + 1) % every == 0:
                    rows.append((t_ref[k + 1], v_ref[k + 1], veh.v, w_m, b.T_ref, e.T_cmd, e.T_max, m.T_e,
                                 m.T_shaft, e.i_d, e.i_q, I, I_opt, u_dc, m.P_elec, P_dc, b.F_brake,
                                 bat.soc, int(e.region)))
                if bar:
                    bar.update()
    finally:
        if ref is not None:
            ref.close()
        if bar:
            bar.close()
    wall = time.perf_counter() - wall0
    Wh = 1 / 3600.0
    km = veh.distance / 1000.0
    summary = dict(
        cycle=cycle.name, method=spec.method, recursion=spec.recursion, conditions=asdict(cond),
        distance_km=km, energy_battery_Wh=bat.E_terminal * Wh, Wh_per_km=bat.E_terminal * Wh / km,
        speed_rmse_mps=math.sqrt(acc["speed_err2"] / n),
        torque_rmse_Nm=math.sqrt(acc["T_err2"] / max(acc["n_T"], 1)), torque_error_max_Nm=acc["T_err_max"],
        torque_cmd_rms_Nm=math.sqrt(acc["T_cmd2"] / max(acc["n_T"], 1)),
        copper_loss_Wh=acc["E_cu"] * Wh, copper_loss_optimal_Wh=acc["E_cu_opt"] * Wh if ref else None,
        time_above_V_max_pct=100.0 * acc["t_over"] / (n * dt), time_voltage_limited_s=acc["t_sat"], time_voltage_limited_pct=100.0 * acc["t_sat"] / (n * dt),
        current_excess_rms_A=math.sqrt(acc["I_excess2"] / acc["n_I"]) if acc["n_I"] else 0.0,
        iron_loss_Wh=acc["E_fe"] * Wh, motor_electric_Wh=acc["E_elec"] * Wh, shaft_Wh=acc["E_mech"] * Wh,
        battery_internal_loss_Wh=(bat.E_loss_R0 + bat.E_loss_R1) * Wh, battery_energy_residual_Wh=bat.energy_residual() * Wh, inverter_loss_Wh=acc["E_inv"] * Wh, aux_Wh=spec.P_aux * n * dt * Wh,
        friction_brake_Wh=veh.E_brake * Wh, regen_curtailed_Wh=bat.E_curtailed * Wh, soc_end=bat.soc,
        steps=n * n_inner, vehicle_steps=n, h_s=spec.h, dt_s=dt, wall_s=wall, real_time_factor=n * dt / wall,
        backend=cosim.backend_name,
    )
    if out is not None:
        write_results(out, summary, rows)
    return summary


def write_results(out: Path, summary: dict, rows: list) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    with open(out / "trace.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(TRACE_COLUMNS)
        w.writerows(rows)
