"""Driver and brake blending, and an "ideal drive" run of a whole cycle from the vehicle-side
models alone (no FMUs): `python -m scenarios.vehicle.driver [CYCLE ...]`.

The driver is a speed PI with feed-forward of the force the trace needs (m_eff a_ref plus the
road load), so the PI only corrects what the model does not know (mass, road load, limits);
it outputs a wheel-force demand. The brake blending turns that demand into a motor torque
command T_ref and a friction-brake force: traction goes to the motor up to its reach (the
controller's T_max), braking goes to the motor first (series regenerative braking) up to the
smaller of T_max and the torque whose power the DC side can take (battery charge limit plus
the auxiliary load), and the friction brakes take the rest. Traction beyond the motor's reach
is simply unmet, and reported.

One vehicle step (dt = 10 ms), as `simulate_ideal` does it and as the co-simulation master
does it with the FMUs in place of the ideal motor:

    F_dem = driver.demand(v_ref(t), v_ref(t + dt), vehicle.v, dt)
    b = blend(F_dem, vehicle.v, T_max, battery.max_charge_power(dt) + P_aux, vp)
    ... drive runs the step with T_ref = b.T_ref, w_m = motor_speed(vehicle.v), u_dc = battery.u ...
    F_w = wheel_force(T_shaft_mean, vp); driver.applied(F_w - b.F_brake)
    vehicle.step(F_w, b.F_brake, dt)
    battery.step(P_elec_mean + P_inverter + P_aux, dt)
"""
from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass, field

import numpy as np

from scenarios.vehicle.battery import Battery, BatteryParams
from scenarios.vehicle.cycles import STANDARD_CYCLES, Cycle, load_cycle
from scenarios.vehicle.longitudinal import (
    Vehicle,
    VehicleParams,
    motor_speed,
    running_resistance,
    shaft_torque,
    wheel_force,
)

#: auxiliary (low-voltage) load on the DC link, W: FASTSim's `auxKw` = 0.25 in its EV files
#: (NREL FASTSim vehicle database, e.g. 2021_Cupra_Born.csv); dynamometer tests run with HVAC off
P_AUX_DEFAULT = 250.0


@dataclass
class DriverParams:
    """Speed PI with feed-forward. Gains from the vehicle's m_eff: kp = m_eff w_c puts the
    loop's crossover at w_c; ki = kp w_c / 4 places the PI zero a factor 4 below it, which gives
    a critically damped double pole at w_c / 2. w_c = 2 rad/s: a 1 s recovery, well inside the
    schedules' tolerance (EPA: +-2 mph within +-1 s; GTR 15: +-2 km/h within +-1 s)."""

    bandwidth: float = 2.0        # rad/s, crossover w_c
    zero_ratio: float = 0.25      # PI zero / crossover
    feedforward: bool = True


class Driver:
    """Wheel-force demand from the speed trace. `applied()` after each step (the force the
    wheels really got, brakes included) stops the integrator winding up when the demand is
    not met (clamping: the step's integration is undone if it pushed further into the limit)."""

    def __init__(self, vp: VehicleParams | None = None, dp: DriverParams | None = None):
        vp = vp if vp is not None else VehicleParams()
        dp = dp if dp is not None else DriverParams()
        self.vp, self.dp = vp, dp
        self.m_eff = vp.m_eff
        self.kp = self.m_eff * dp.bandwidth
        self.ki = self.kp * dp.bandwidth * dp.zero_ratio
        self.integral = 0.0     # N
        self._last = None       # (error, integration increment, demand) of the last call

    def feedforward(self, v_ref: float, v_ref_next: float, dt: float) -> float:
        """Force that takes the model from v_ref to v_ref_next in one explicit step, N."""
        if v_ref <= 0.0 and v_ref_next <= 0.0:
            return 0.0
        return self.m_eff * (v_ref_next - v_ref) / dt + running_resistance(v_ref, self.vp)

    def demand(self, v_ref: float, v_ref_next: float, v: float, dt: float) -> float:
        """Wheel-force demand (N) for the step from t to t + dt."""
        if v_ref <= 0.0 and v_ref_next <= 0.0 and v <= 0.0:
            # standing with a standing trace: nothing to do; the brakes hold the car
            self.integral = 0.0
            self._last = None
            return 0.0
        e = v_ref - v
        dI = self.ki * e * dt
        self.integral += dI
        F_ff = self.feedforward(v_ref, v_ref_next, dt) if self.dp.feedforward else 0.0
        F = F_ff + self.kp * e + self.integral
        self._last = (e, dI, F)
        return F

    def applied(self, F_applied: float, tol: float = 1e-6) -> None:
        """Anti-windup: if the wheels got less than demanded (or more braking) and the error
        asks for more in the same direction, take back this step's integration."""
        if self._last is None:
            return
        e, dI, F = self._last
        short = F - F_applied
        if abs(short) > tol * max(1.0, abs(F)) and short * e > 0.0:
            self.integral -= dI
        self._last = None


@dataclass
class BlendParams:
    """Series regenerative braking. regen_fade_speed: below it the regen reach falls linearly to
    zero (production cars do this near standstill for comfort; energy-wise regen pays down to
    ~0.2 m/s with the default motor, where its copper loss equals the power recovered), so the
    default leaves regen on down to standstill."""

    regen_fade_speed: float = 0.0   # m/s


@dataclass(slots=True)
class Blend:
    T_ref: float             # N m, motor torque command (the controller may clamp it further)
    F_brake: float           # N >= 0, friction-brake force
    F_unmet_traction: float  # N >= 0, traction beyond the motor's reach
    F_unmet_braking: float   # N >= 0, braking beyond the friction brakes' limit
    regen_limit: str = ""    # "", "motor" (T_max), "battery" (charge power) or "fade"


def blend(F_demand: float, v: float, T_max: float, P_regen_max: float,
          vp: VehicleParams | None = None, bp: BlendParams | None = None) -> Blend:
    """Split a wheel-force demand (N) at speed v (m/s) into T_ref and friction braking.
    T_max: the motor's reach now (N m, magnitude; the controller's T_max output). P_regen_max:
    the electric power (W, >= 0) the DC side can take back; the torque limit P_regen_max / w_m
    ignores the drive's losses, which only make the power returned smaller (conservative).
    vp, bp: None for the defaults."""
    vp = vp if vp is not None else VehicleParams()
    bp = bp if bp is not None else BlendParams()
    T_max = abs(T_max)
    if F_demand >= 0.0:
        T = min(shaft_torque(F_demand, vp), T_max)
        return Blend(T, 0.0, max(0.0, F_demand - wheel_force(T, vp)), 0.0)
    F_brake_max = vp.brake_force_max
    if v <= 0.0:
        F_b = min(-F_demand, F_brake_max)
        return Blend(0.0, F_b, 0.0, -F_demand - F_b)
    w_m = motor_speed(v, vp)
    T_lim, why = T_max, "motor"
    T_batt = max(P_regen_max, 0.0) / w_m
    if T_batt < T_lim:
        T_lim, why = T_batt, "battery"
    if bp.regen_fade_speed > 0.0 and v < bp.regen_fade_speed:
        T_fade = T_lim * v / bp.regen_fade_speed
        T_lim, why = T_fade, "fade"
    T_need = shaft_torque(F_demand, vp)          # < 0
    T = max(T_need, -T_lim)
    F_rest = max(0.0, wheel_force(T, vp) - F_demand)  # braking the motor cannot give (0 up to rounding)
    F_b = min(F_rest, F_brake_max)
    return Blend(T, F_b, 0.0, F_rest - F_b, why if T > T_need else "")


# -- ideal drive: the vehicle-side models with an idealised motor, no FMUs ------------------

@dataclass
class IdealMotor:
    """Constant-efficiency motor with the default motor's envelope (docs/motor/targets.json:
    285.4 N m peak, 113.4 kW peak shaft power, at 355 V)."""

    efficiency: float = 0.92      # motor alone, both directions (assumed: a cycle average of the class)
    T_peak: float = 285.4         # N m
    P_peak: float = 113.4e3       # W

    def T_max(self, w_m: float) -> float:
        return self.T_peak if w_m * self.T_peak <= self.P_peak else self.P_peak / w_m

    def P_elec(self, T: float, w_m: float) -> float:
        P = T * w_m
        return P / self.efficiency if P >= 0.0 else P * self.efficiency


@dataclass
class IdealInverter:
    """Constant efficiency, both directions: the loss is (1 - efficiency) |P_ac|. The default is
    the cycle average of the inverter loss model the FMUs compute (fmu_src/inverter/inverter_loss.hpp,
    through IpmsmPlant and IpmsmDrive), measured on WLTC 3b with the default drive:
    1 - E_inv / int |P_elec| dt (docs/vehicle.md: "Ideal-drive energy estimate" gives the command).
    A constant, as the ideal motor's: this estimate has no phase current for the model to work on."""

    efficiency: float = 0.978

    def loss(self, P_ac: float) -> float:
        return (1.0 - self.efficiency) * abs(P_ac)


@dataclass
class IdealDriveSpec:
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    driver: DriverParams = field(default_factory=DriverParams)
    blend: BlendParams = field(default_factory=BlendParams)
    battery: BatteryParams = field(default_factory=BatteryParams)
    inverter: IdealInverter = field(default_factory=IdealInverter)
    motor: IdealMotor = field(default_factory=IdealMotor)
    P_aux: float = P_AUX_DEFAULT  # W
    dt: float = 0.01              # s, vehicle step


@dataclass(frozen=True)
class IdealDriveSummary:
    """What `simulate_ideal` returns: the energy flows of the cycle, Wh (the battery's at its
    terminals; shaft_regen_Wh and wheel_regen_Wh <= 0), and the speed tracking."""

    cycle: str
    distance_km: float
    duration_s: float
    speed_rmse_kmh: float
    speed_err_max_kmh: float
    F_unmet_traction_max_N: float
    wheel_traction_Wh: float
    wheel_regen_Wh: float
    friction_brake_Wh: float
    shaft_motoring_Wh: float
    shaft_regen_Wh: float
    motor_loss_Wh: float
    inverter_loss_Wh: float
    aux_Wh: float
    battery_internal_loss_Wh: float
    regen_curtailed_Wh: float
    energy_battery_Wh: float
    Wh_per_km: float
    Wh_per_km_no_aux: float
    soc_end: float
    #: with trace=True, a row per step: t, v_ref, v, T, w_m, F_brake, P_elec, P_inverter, u_dc, soc
    trace: np.ndarray | None = None


def simulate_ideal(cycle: Cycle, spec: IdealDriveSpec | None = None, trace: bool = False) -> IdealDriveSummary:
    """Drive `cycle` with the ideal motor; energies in Wh, the battery's at its terminals."""
    spec = spec if spec is not None else IdealDriveSpec()
    vp, dt = spec.vehicle, spec.dt
    veh = Vehicle(vp)
    drv = Driver(vp, spec.driver)
    bat = Battery(spec.battery)
    mot = spec.motor
    n = int(round(cycle.duration_s / dt))
    t = cycle.time_s[0] + dt * np.arange(n + 1)
    v_ref = cycle.speed_at(t).tolist()   # Python floats: the loop is scalar
    E = dict(motor_loss=0.0, inverter_loss=0.0, aux=0.0, shaft_pos=0.0, shaft_neg=0.0)
    F_unmet_max = 0.0
    err2 = 0.0
    err_max = 0.0
    rows = [] if trace else None
    for k in range(n):
        v = veh.v
        F_dem = drv.demand(v_ref[k], v_ref[k + 1], v, dt)
        w_m = motor_speed(v, vp)
        b = blend(F_dem, v, mot.T_max(w_m), bat.max_charge_power(dt) + spec.P_aux, vp, spec.blend)
        T = b.T_ref
        F_w = wheel_force(T, vp)
        drv.applied(F_w - b.F_brake)
        veh.step(F_w, b.F_brake, dt)
        P_mech = T * w_m
        P_el = mot.P_elec(T, w_m)
        P_inv = spec.inverter.loss(P_el)
        bat.step(P_el + P_inv + spec.P_aux, dt)
        E["motor_loss"] += (P_el - P_mech) * dt
        E["inverter_loss"] += P_inv * dt
        E["aux"] += spec.P_aux * dt
        E["shaft_pos" if P_mech >= 0 else "shaft_neg"] += P_mech * dt
        F_unmet_max = max(F_unmet_max, b.F_unmet_traction)
        e = veh.v - v_ref[k + 1]
        err2 += e * e
        err_max = max(err_max, abs(e))
        if trace:
            rows.append((t[k + 1], v_ref[k + 1], veh.v, T, w_m, b.F_brake, P_el, P_inv, bat.u, bat.soc))
    Wh = 1 / 3600.0
    km = veh.distance / 1000.0
    return IdealDriveSummary(
        cycle=cycle.name, distance_km=km, duration_s=n * dt,
        speed_rmse_kmh=math.sqrt(err2 / n) * 3.6, speed_err_max_kmh=err_max * 3.6,
        F_unmet_traction_max_N=F_unmet_max,
        wheel_traction_Wh=veh.E_traction * Wh, wheel_regen_Wh=veh.E_regen * Wh,
        friction_brake_Wh=veh.E_brake * Wh,
        shaft_motoring_Wh=E["shaft_pos"] * Wh, shaft_regen_Wh=E["shaft_neg"] * Wh,
        motor_loss_Wh=E["motor_loss"] * Wh, inverter_loss_Wh=E["inverter_loss"] * Wh,
        aux_Wh=E["aux"] * Wh,
        battery_internal_loss_Wh=(bat.E_loss_R0 + bat.E_loss_R1) * Wh,
        regen_curtailed_Wh=bat.E_curtailed * Wh,
        energy_battery_Wh=bat.E_terminal * Wh,
        Wh_per_km=bat.E_terminal * Wh / km,
        Wh_per_km_no_aux=(bat.E_terminal - E["aux"]) * Wh / km,
        soc_end=bat.soc,
        trace=np.array(rows) if trace else None,
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m scenarios.vehicle.driver",
                                 description="Ideal-drive energy per cycle from the vehicle-side models alone.")
    ap.add_argument("cycles", nargs="*", default=list(STANDARD_CYCLES), help="names or CSV paths")
    ap.add_argument("--eta-motor", type=float, default=IdealMotor.efficiency)
    ap.add_argument("--eta-inverter", type=float, default=IdealInverter.efficiency)
    ap.add_argument("--soc0", type=float, default=BatteryParams.soc0)
    ap.add_argument("--aux", type=float, default=P_AUX_DEFAULT, help="auxiliary load, W")
    args = ap.parse_args(argv)
    spec = IdealDriveSpec(motor=IdealMotor(efficiency=args.eta_motor),
                          inverter=IdealInverter(efficiency=args.eta_inverter),
                          battery=BatteryParams(soc0=args.soc0), P_aux=args.aux)
    cols = [("cycle", "{:>7}"), ("distance_km", "{:8.4f}"), ("speed_rmse_kmh", "{:6.3f}"),
            ("wheel_traction_Wh", "{:7.0f}"), ("wheel_regen_Wh", "{:7.0f}"), ("friction_brake_Wh", "{:6.0f}"),
            ("motor_loss_Wh", "{:6.0f}"), ("inverter_loss_Wh", "{:6.0f}"), ("aux_Wh", "{:5.0f}"),
            ("battery_internal_loss_Wh", "{:5.0f}"), ("energy_battery_Wh", "{:7.0f}"), ("Wh_per_km", "{:6.1f}"),
            ("Wh_per_km_no_aux", "{:6.1f}")]
    print(f"ideal drive: motor efficiency {args.eta_motor:.3f}, inverter {args.eta_inverter:.4f}, SOC0 {args.soc0}, "
          f"aux {args.aux:g} W, m_eff {spec.vehicle.m_eff:.1f} kg")
    print(" ".join(c for c, _ in cols))
    for name in args.cycles:
        t0 = time.perf_counter()
        r = simulate_ideal(load_cycle(name), spec)
        print(" ".join(f.format(getattr(r, c)) for c, f in cols), f"({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
