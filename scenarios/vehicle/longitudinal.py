"""Vehicle longitudinal model: a point mass on a road of constant grade (flat by default) with
the chassis-dynamometer road load, a single-speed reduction gear with one efficiency, and the
rotating parts lumped into an equivalent mass. SI units throughout; speeds v >= 0 (forward driving only).

Defaults: a C-segment EV like the 2022 Nissan Leaf 40 kWh; sources and status per field below
and in docs/vehicle.md.

Sign conventions: wheel (tractive) force F > 0 drives forward; the friction-brake force is a
magnitude >= 0 that opposes motion; shaft torque T > 0 is motoring, T < 0 regenerating.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: standard gravity (CGPM 1901), m/s^2
G_N = 9.80665

#: density of non-oriented electrical steel, kg/m^3 (M270-35A class, EN 10106 gives 7.65 g/cm^3
#: for this loss grade); the rotor is laminations plus NdFeB (7.5 g/cm^3), so the same value
ROTOR_DENSITY = 7650.0


def solid_rotor_inertia(diameter: float, length: float, density: float = ROTOR_DENSITY) -> float:
    """J = (pi/32) rho L d^4 of a solid cylinder, kg m^2. Used for the motor's rotor: the magnet
    pockets and shaft bore lower it, the shaft ends and the gear's input pinion raise it."""
    return math.pi / 32.0 * density * length * diameter ** 4


#: the default motor's rotor (docs/motor/README.md: rotor 171 mm, stack 120 mm): 0.077 kg m^2
J_MOTOR_DEFAULT = solid_rotor_inertia(0.171, 0.120)

#: one road wheel with tyre and brake disc, kg m^2: FASTSim's default `wheelInertiaKgM2`
#: (NREL FASTSim vehicle database, e.g. resources/vehdb/2021_Cupra_Born.csv)
J_WHEEL_DEFAULT = 0.815


@dataclass
class VehicleParams:
    """Longitudinal parameters. Road load F = A + B v + C v^2 (v in m/s) is the dynamometer
    target curve, which already holds tyre rolling resistance, aerodynamic drag and the
    driveline's spin losses measured in a coast-down; so driveline_efficiency covers only the
    loss under load (gear mesh), applied as a torque ratio. Mass, road load and driveline
    efficiency are assumed values of a Leaf-class car, not a published test record
    (docs/vehicle.md gives each value's status)."""

    mass: float = 1758.0            # kg, test mass (= 3875 lb, an equivalent-test-weight class of 40 CFR 1066.805)
    road_load_A: float = 115.16     # N         (= 25.89 lbf: EPA target-coefficient form, 40 CFR 1066.301)
    road_load_B: float = 3.4319     # N/(m/s)   (= 0.3449 lbf/mph)
    road_load_C: float = 0.4329     # N/(m/s)^2 (= 0.01945 lbf/mph^2)
    gear_ratio: float = 8.19        # motor speed / wheel speed (the Leaf's single-speed reduction, 8.193)
    wheel_radius: float = 0.306     # m, dynamic rolling radius (205/55 R16: 316 mm free, ~3 % less under load)
    driveline_efficiency: float = 0.97  # assumed: single-stage helical reduction + differential, under load
    J_motor: float = J_MOTOR_DEFAULT    # kg m^2, rotor (and what turns at motor speed)
    J_wheels: float = 4 * J_WHEEL_DEFAULT  # kg m^2, all four wheels (the car on the road)
    tyre_road_friction: float = 0.8     # mu, dry asphalt (FASTSim `wheelCoefOfFric` default)
    grade: float = 0.0                  # road grade, rise over run (0.08: 8 % uphill; < 0 downhill)

    @property
    def rotating_mass(self) -> float:
        """Equivalent translational mass of the rotating parts, kg: (J_w + J_m k^2) / r^2."""
        return (self.J_wheels + self.J_motor * self.gear_ratio ** 2) / self.wheel_radius ** 2

    @property
    def m_eff(self) -> float:
        """Mass to accelerate, kg: test mass plus the rotating parts."""
        return self.mass + self.rotating_mass

    @property
    def brake_force_max(self) -> float:
        """Largest friction-brake force, N: all four wheels at the adhesion limit (mu m g)."""
        return self.tyre_road_friction * self.mass * G_N


def motor_speed(v, p: VehicleParams):
    """Rotor speed w_m (rad/s) at vehicle speed v (m/s): no wheel slip."""
    return v * (p.gear_ratio / p.wheel_radius)


def vehicle_speed(w_m, p: VehicleParams):
    """Inverse of motor_speed."""
    return w_m * (p.wheel_radius / p.gear_ratio)


def wheel_force(T_shaft: float, p: VehicleParams) -> float:
    """Tractive force at the tyres (N) from the motor shaft torque (N m). The gear loses the
    same fraction of the power flowing through it either way: motoring, the wheels get eta of
    the shaft's; regenerating, the shaft gets eta of the wheels' (so the wheels must push 1/eta)."""
    F = T_shaft * p.gear_ratio / p.wheel_radius
    return F * p.driveline_efficiency if T_shaft >= 0.0 else F / p.driveline_efficiency


def shaft_torque(F_wheel: float, p: VehicleParams) -> float:
    """Shaft torque (N m) that yields the wheel force F_wheel (N): the inverse of wheel_force."""
    T = F_wheel * p.wheel_radius / p.gear_ratio
    return T / p.driveline_efficiency if F_wheel >= 0.0 else T * p.driveline_efficiency


def road_load(v, p: VehicleParams):
    """Resistance while rolling forward at v >= 0 (m/s), N: A + B v + C v^2. At v = 0 this is the
    break-away force; longitudinal_step treats it as static there (the car does not roll back)."""
    return p.road_load_A + (p.road_load_B + p.road_load_C * v) * v


def grade_force(p: VehicleParams) -> float:
    """The weight's component along a road of grade p.grade (rise over run), N: m g sin(atan
    grade), the grade resistance R_g = W sin(theta) of Gillespie, Fundamentals of Vehicle
    Dynamics (SAE, 1992), ch. 4; on the test mass alone (the rotating parts' weight is in it)."""
    return p.mass * G_N * p.grade / math.sqrt(1.0 + p.grade * p.grade)


def running_resistance(v, p: VehicleParams):
    """What the wheels push against at v >= 0 (m/s), N: the road load and the grade."""
    return road_load(v, p) + grade_force(p)


def longitudinal_step(v: float, F_wheel: float, F_brake: float, dt: float,
                      p: VehicleParams) -> tuple[float, float]:
    """One explicit (forward Euler) step of m_eff dv/dt = F_wheel - F_brake - F_road(v) - F_grade.

    Resistances (road load, grade and brakes) cannot reverse the car: at standstill they hold it
    unless the tractive force exceeds them (on a hill: as the driver's brake would), and a step
    that would cross zero stops at zero.
    Returns (v_next, distance travelled in the step) with the trapezoidal rule.
    """
    if F_brake < 0.0:
        raise ValueError(f"F_brake is a magnitude, got {F_brake} N")
    if v < 0.0:
        raise ValueError(f"forward driving only, got v = {v} m/s")
    F_net = F_wheel - F_brake - running_resistance(v, p)
    v_next = v + dt * F_net / p.m_eff
    if v_next < 0.0:
        v_next = 0.0
    return v_next, 0.5 * (v + v_next) * dt


class Vehicle:
    """State (speed, distance, time) stepped by longitudinal_step; keeps the energy bookkeeping
    at the wheels: tractive work (positive and negative) and friction-brake work."""

    def __init__(self, p: VehicleParams | None = None, v0: float = 0.0):
        self.p = p if p is not None else VehicleParams()
        self.v = float(v0)
        self.distance = 0.0
        self.t = 0.0
        self.E_traction = 0.0   # J, work of positive wheel force
        self.E_regen = 0.0      # J, work of negative wheel force (<= 0)
        self.E_brake = 0.0      # J, dissipated by friction brakes (>= 0)

    @property
    def w_m(self) -> float:
        return motor_speed(self.v, self.p)

    def step(self, F_wheel: float, F_brake: float, dt: float) -> float:
        v_next, dx = longitudinal_step(self.v, F_wheel, F_brake, dt, self.p)
        if F_wheel >= 0.0:
            self.E_traction += F_wheel * dx
        else:
            self.E_regen += F_wheel * dx
        self.E_brake += F_brake * dx
        self.v = v_next
        self.distance += dx
        self.t += dt
        return v_next


def coastdown_time(v0: float, p: VehicleParams) -> float:
    """Analytic time (s) to coast from v0 to rest under the road load alone:
    m dv/dt = -(A + B v + C v^2), with D = 4AC - B^2 > 0:
    t = 2 m / sqrt(D) * [atan((2 C v0 + B)/sqrt(D)) - atan(B/sqrt(D))]."""
    A, B, C, m = p.road_load_A, p.road_load_B, p.road_load_C, p.m_eff
    D = 4 * A * C - B * B
    if D <= 0:
        raise ValueError("coastdown_time needs 4AC > B^2")
    s = math.sqrt(D)
    return 2 * m / s * (math.atan((2 * C * v0 + B) / s) - math.atan(B / s))


def coastdown_speed(t, v0: float, p: VehicleParams):
    """Analytic coast-down speed (m/s) at time t (s) from v0; 0 after coastdown_time."""
    A, B, C, m = p.road_load_A, p.road_load_B, p.road_load_C, p.m_eff
    s = math.sqrt(4 * A * C - B * B)
    th = np.arctan((2 * C * v0 + B) / s) - np.asarray(t, float) * s / (2 * m)
    v = (s * np.tan(th) - B) / (2 * C)
    return np.where(np.asarray(t) < coastdown_time(v0, p), v, 0.0)
