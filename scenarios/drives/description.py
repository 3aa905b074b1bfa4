"""Drive descriptions: one TOML file names a drive's motor (its flux map and parameters),
inverter, battery, vehicle, controller settings and CI checks (docs/spec/INTERFACE.md,
"Drive description (TOML)"; every key, unit, default and source: docs/drives.md).

    >>> d = load_drive("scenarios/drives/city_ev.toml")   # None: scenarios/drives/default.toml
    >>> d.motor.pole_pairs, d.vehicle.mass, d.battery.n_series

The schema is written once, in SCHEMA: a key's section, name, kind, unit, the rule its value
must obey and where its default comes from. The defaults are the project's default EV: the
dataclasses of the vehicle side (VehicleParams, BatteryParams, P_AUX_DEFAULT), for the
inverter the plant FMU's own (the start values of its modelDescription: the C++ model's), and,
for the motor, the `# key: value` metadata of the named flux map (the map's own data sheet),
else of the default motor's map, each such value named in `DriveDescription.assumed`
(scenarios.maps.machine). Paths are relative to the file. A bad file raises
DriveDescriptionError naming the file, the key and what was expected.
"""
from __future__ import annotations

import difflib
import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from scenarios.core.boundary import InputError, load_toml
from scenarios.core.constants import ZERO_CELSIUS_K
from scenarios.core.fmu_ranges import PLANT_DESCRIPTION, Range, controller_has_objective, fmu_ranges, read_starts
from scenarios.core.paths import PACKAGE_DIR, ROOT, located
from scenarios.maps.error import MapImportError
from scenarios.maps.flux_map import DEFAULT_MAP, FluxMap, MotorData, read_flux_map
from scenarios.maps.machine import machine_values
from scenarios.maps.metadata import MetadataError, metadata_keys, metadata_value
from scenarios.vehicle.battery import OCV_FITS, BatteryParams
from scenarios.vehicle.driver import P_AUX_DEFAULT
from scenarios.vehicle.longitudinal import VehicleParams

#: the project's drives; `default.toml` is what no --drive means
DRIVES_DIR = PACKAGE_DIR / "drives"
DEFAULT_DRIVE = DRIVES_DIR / "default.toml"

#: the controller's methods by the contract's names (the FMU's `method` parameter)
METHODS = {"ferrari": 1, "lut_speed": 2, "lut_flux": 3}
#: what the controller minimises for the torque asked, by the drive description's names (the FMU's
#: `objective` parameter; docs/spec/INTERFACE.md, "Least-loss control")
OBJECTIVES = {"current": 0, "loss": 1}

#: the [fault] table's safe states by IpmsmDrive's `safe_state` values (contract, "Faults")
SAFE_STATES = {"by_speed": 0, "freewheel": 1, "asc": 2}
#: the [fault] table's triggers: exactly one is given
FAULT_TRIGGERS = ("t_s", "speed_rpm", "v_kmh")


class DriveDescriptionError(InputError):
    """A drive description that cannot be used: which file, which key, what was expected."""


# -- the schema ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Rule:
    """What a value must be: a kind (real, int, str, path, strings) and a physical range."""

    kind: str                  # "real", "int", "bool", "str", "path", "strings"
    lo: float | None = None    # bounds, inclusive unless open
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple = ()

    def describe(self) -> str:
        what = {"real": "a number", "int": "an integer", "bool": "true or false", "str": "a string",
                "path": "a file path (string)",
                "strings": "a list of strings"}[self.kind]
        if self.choices:
            what += " out of " + ", ".join(repr(c) for c in self.choices)
        if self.lo is not None and self.hi is not None:
            what += f" in {'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"
        elif self.lo is not None:
            what += f" {'>' if self.lo_open else '>='} {self.lo:g}"
        elif self.hi is not None:
            what += f" {'<' if self.hi_open else '<='} {self.hi:g}"
        return what

    def within(self, r: Range | None) -> Rule:
        """This rule narrowed to an FMU parameter's range (scenarios.core.fmu_ranges)."""
        if r is None:
            return self
        lo, lo_open, hi, hi_open = self.lo, self.lo_open, self.hi, self.hi_open
        if r.lo is not None and (lo is None or r.lo > lo):
            lo, lo_open = r.lo, False
        if r.hi is not None and (hi is None or r.hi < hi):
            hi, hi_open = r.hi, False
        return replace(self, lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open)

    def check(self, value: Any) -> str | None:
        """None if `value` obeys the rule, else what was expected (for the error)."""
        k = self.kind
        if k == "real":
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not _finite(value):
                return self.describe()
        elif k == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                return self.describe()
        elif k == "bool":
            if not isinstance(value, bool):
                return self.describe()
        elif k in ("str", "path"):
            if not isinstance(value, str) or not value:
                return self.describe()
            if "\0" in value or len(value) > MAX_TEXT:
                return self.describe() + f" without NUL characters, at most {MAX_TEXT} characters"
        elif k == "strings":
            if (not isinstance(value, list) or not value or len(value) > MAX_LIST or
                    not all(isinstance(s, str) and s and "\0" not in s and len(s) <= MAX_TEXT for s in value)):
                return f"a non-empty list of at most {MAX_LIST} strings (no NUL, at most {MAX_TEXT} characters each)"
        if self.choices and value not in self.choices:
            return self.describe()
        if k in ("real", "int"):
            if k == "int" and abs(value) > 2**53:
                return self.describe() + f", got an integer of {len(str(abs(value)))} digits"
            if self.lo is not None and (value < self.lo or (self.lo_open and value == self.lo)):
                return self.describe() + f", got {value!r}"
            if self.hi is not None and (value > self.hi or (self.hi_open and value == self.hi)):
                return self.describe() + f", got {value!r}"
        return None


def _finite(x) -> bool:
    try:
        return math.isfinite(x)
    except OverflowError:  # an integer beyond a float's range (TOML allows 400 digits)
        return False


#: a name or path longer than this is no name (the FMUs' log lines are shorter)
MAX_TEXT = 1024
#: checks.cycles: more cycles than this is no CI gate
MAX_LIST = 100

POSITIVE = Rule("real", lo=0.0, lo_open=True)
NON_NEGATIVE = Rule("real", lo=0.0)
FRACTION = Rule("real", lo=0.0, hi=1.0, lo_open=True)   # an efficiency, a utilisation
TEMPERATURE = Rule("real", lo=173.15, hi=573.15)         # K, the FMUs' range of T_magnet_ref
COEFFICIENT = Rule("real", lo=-0.01, hi=0.01)            # 1/K, the FMUs' range of k_psi_T
#: K, a temperature a drive operates at (coolant, ambient, the derating's maxima): not below -40 degC,
#: the lowest operating temperature of automotive electronics (AEC-Q100's grades 0-3) and of the
#: climatic tests of ISO 16750-4; a number below it can only be a degC value given as K
OPERATING_TEMPERATURE = Rule("real", lo=233.15, hi=573.15)


#: the thermal network's speed-dependent links a exp(-n / b) + c (contract, "Thermal")
LPTN_SPEED_LINKS = (("tooth_magnet", "teeth - magnet"), ("winding_magnet", "winding - magnet"),
                    ("magnet_ambient", "magnet - ambient"))


@dataclass(frozen=True)
class Key:
    """One key of the schema. `default` documents where a missing key's value comes from; the
    value itself is computed by the loader (from the dataclasses or the map's metadata).
    `acts` says when the key changes a run (the tests perturb each key under that condition)."""

    section: str
    name: str
    rule: Rule
    unit: str
    meaning: str
    default: str
    acts: str = "always"

    @property
    def path(self) -> str:
        return f"{self.section}.{self.name}" if self.section else self.name


def _dc(cls, name: str) -> str:
    return f"{cls.__name__}.{name}"


#: where an inverter key's default comes from: the FMU that computes the loss
_PLANT_DEFAULT = "the plant FMU's default (its modelDescription start)"


def _meta(key: str) -> str:
    return f"map metadata `{key}`"


SCHEMA: tuple[Key, ...] = (
    Key("", "name", Rule("str"), "", "the drive's name in summaries and reports", "the file's stem"),
    # [motor]: FMU parameters of the controller and the plant, and the rotor's inertia
    Key("motor", "flux_map", Rule("path"), "", "flux-map file (the contract's CSV; a FEM export the scenarios "
        "import), relative to this file; REQUIRED", "none: required"),
    Key("motor", "pole_pairs", Rule("int", lo=1, hi=100), "", "pole pairs p", _meta("pole_pairs")),
    Key("motor", "R_s", POSITIVE, "Ohm", "stator resistance per phase at T_winding_ref", _meta("R_s_ohm")),
    Key("motor", "I_max", Rule("real", lo=0.0, hi=1e5, lo_open=True), "A", "peak current limit", _meta("I_max_A")),
    Key("motor", "T_magnet_ref", TEMPERATURE, "K", "magnet temperature at which the map holds",
        _meta("T_magnet_ref_K")),
    Key("motor", "T_winding_ref", TEMPERATURE, "K", "winding temperature at which R_s holds",
        _meta("T_winding_ref_K")),
    Key("motor", "alpha_cu", Rule("real", lo=0.0, hi=0.01), "1/K", "temperature coefficient of R_s",
        _meta("alpha_cu_per_K")),
    Key("motor", "k_psi_T", COEFFICIENT, "1/K", "relative change of the magnet flux per kelvin",
        _meta("k_psi_T_per_K")),
    Key("motor", "J", Rule("real", lo=0.0, hi=100.0, lo_open=True),
        "kg m^2", "rotor inertia (and what turns at motor speed)",
        _dc(VehicleParams, "J_motor")),
    Key("motor", "w_m_max", Rule("real", lo=0.0, hi=1e5, lo_open=True),
        "rad/s", "top speed: the end of the 2-D tables' speed axis (and of "
        "`sweep`'s speeds); the vehicle side flags a run above it (summary `time_above_top_speed_s`)",
        _meta("w_m_max_rad_s"), acts="method lut_speed"),
    Key("motor", "fe_k_h", NON_NEGATIVE, "W/Hz", "iron loss: hysteresis coefficient at fe_psi_ref",
        _meta("fe_k_h_W_per_Hz")),
    Key("motor", "fe_alpha", Rule("real", lo=1.0, hi=3.0), "1", "iron loss: Steinmetz exponent",
        _meta("fe_alpha")),
    Key("motor", "fe_k_e", NON_NEGATIVE, "W/Hz^2", "iron loss: eddy-current coefficient at fe_psi_ref",
        _meta("fe_k_e_W_per_Hz2")),
    Key("motor", "fe_psi_ref", POSITIVE, "Wb", "iron loss: flux linkage of the coefficients",
        _meta("fe_psi_ref_Wb")),
    # [inverter]: the parameters of the plant FMU's inverter loss model (fmu_src/inverter/inverter_loss.hpp;
    # IpmsmDrive's are the plant's), by the FMUs' names
    Key("inverter", "f_sw", POSITIVE, "Hz", "switching frequency", _PLANT_DEFAULT),
    Key("inverter", "V_T0", NON_NEGATIVE, "V", "IGBT threshold voltage", _PLANT_DEFAULT),
    Key("inverter", "r_T", NON_NEGATIVE, "Ohm", "IGBT slope resistance", _PLANT_DEFAULT),
    Key("inverter", "V_D0", NON_NEGATIVE, "V", "diode threshold voltage", _PLANT_DEFAULT),
    Key("inverter", "r_D", NON_NEGATIVE, "Ohm", "diode slope resistance", _PLANT_DEFAULT),
    Key("inverter", "E_on", NON_NEGATIVE, "J", "turn-on energy at I_ref, V_ref", _PLANT_DEFAULT),
    Key("inverter", "E_off", NON_NEGATIVE, "J", "turn-off energy at I_ref, V_ref", _PLANT_DEFAULT),
    Key("inverter", "E_rec", NON_NEGATIVE, "J", "diode recovery energy at I_ref, V_ref", _PLANT_DEFAULT),
    Key("inverter", "I_ref", Rule("real", lo=0.0, hi=1e5, lo_open=True),
        "A", "test current of the switching energies", _PLANT_DEFAULT),
    Key("inverter", "V_ref", Rule("real", lo=0.0, hi=1e5, lo_open=True),
        "V", "test DC voltage of the switching energies", _PLANT_DEFAULT),
    Key("inverter", "k_v", Rule("real", lo=0.0, hi=3.0), "1", "exponent of the switching energies' voltage "
        "scaling", _PLANT_DEFAULT),
    # [battery]: scenarios/battery.py's equivalent circuit
    Key("battery", "n_series", Rule("int", lo=1, hi=10_000), "", "cells in series", _dc(BatteryParams, "n_series")),
    Key("battery", "n_parallel", Rule("int", lo=1, hi=10_000),
        "", "cells in parallel", _dc(BatteryParams, "n_parallel")),
    Key("battery", "cell_capacity_Ah", Rule("real", lo=0.0, hi=1e4, lo_open=True),
        "Ah", "capacity of one cell", _dc(BatteryParams, "cell_capacity_Ah"),
        acts="always (SOC moves)"),
    Key("battery", "R0", Rule("real", lo=0.0, hi=100.0, lo_open=True),
        "Ohm", "pack series resistance", _dc(BatteryParams, "R0")),
    Key("battery", "R1", Rule("real", lo=0.0, hi=100.0, lo_open=True),
        "Ohm", "pack polarisation resistance", _dc(BatteryParams, "R1")),
    Key("battery", "tau1", Rule("real", lo=1e-3, hi=1e5),
        "s", "polarisation time constant R1 C1", _dc(BatteryParams, "tau1")),
    Key("battery", "u_cell_max", Rule("real", lo=0.0, hi=10.0, lo_open=True), "V", "charge cut-off voltage per cell",
        _dc(BatteryParams, "u_cell_max"), acts="regenerative braking near a full pack"),
    Key("battery", "soc0", Rule("real", lo=0.0, hi=1.0), "1", "state of charge at the start",
        _dc(BatteryParams, "soc0")),
    Key("battery", "ocv", Rule("str"), "", "cell open-circuit voltage: a shipped fit (" + ", ".join(OCV_FITS) +
        ") or a CSV of soc,ocv_cell_V relative to this file", _dc(BatteryParams, "ocv_fit")),
    # [vehicle]: scenarios/vehicle.py's longitudinal model and the auxiliary load
    Key("vehicle", "mass", Rule("real", lo=1.0, hi=1e5), "kg", "test mass", _dc(VehicleParams, "mass")),
    Key("vehicle", "road_load_A", Rule("real", lo=0.0, hi=1e5), "N", "road load F = A + B v + C v^2: A",
        _dc(VehicleParams, "road_load_A")),
    Key("vehicle", "road_load_B", Rule("real", lo=0.0, hi=1e4),
        "N/(m/s)", "road load: B", _dc(VehicleParams, "road_load_B")),
    Key("vehicle", "road_load_C", Rule("real", lo=0.0, hi=1e3),
        "N/(m/s)^2", "road load: C", _dc(VehicleParams, "road_load_C")),
    Key("vehicle", "gear_ratio", Rule("real", lo=0.1, hi=100.0),
        "1", "motor speed / wheel speed", _dc(VehicleParams, "gear_ratio")),
    Key("vehicle", "wheel_radius", Rule("real", lo=0.01, hi=10.0),
        "m", "dynamic rolling radius", _dc(VehicleParams, "wheel_radius")),
    Key("vehicle", "driveline_efficiency", FRACTION, "1", "gear efficiency under load",
        _dc(VehicleParams, "driveline_efficiency")),
    Key("vehicle", "J_wheels", Rule("real", lo=0.0, hi=1e4),
        "kg m^2", "inertia of all road wheels", _dc(VehicleParams, "J_wheels")),
    Key("vehicle", "tyre_road_friction", Rule("real", lo=0.0, hi=5.0, lo_open=True),
        "1", "tyre-road friction coefficient (friction-brake limit)",
        _dc(VehicleParams, "tyre_road_friction"), acts="braking harder than mu m g"),
    Key("vehicle", "grade", Rule("real", lo=-0.35, hi=0.35), "1", "road grade, rise over run, the whole run "
        "(0.08: 8 % uphill); within the steepest public streets' 35 %", _dc(VehicleParams, "grade")),
    Key("vehicle", "P_aux", Rule("real", lo=0.0, hi=1e6), "W", "auxiliary load on the DC link",
        "scenarios.vehicle.driver.P_AUX_DEFAULT"),
    # [controller]: the controller FMU's settings
    Key("controller", "method", Rule("str", choices=tuple(METHODS)), "", "torque-to-current method",
        "`ferrari` (the FMU's default)"),
    Key("controller", "recursion", Rule("int", lo=0, hi=2), "", "inductance recursion (0, 1, 2)",
        "2 (the FMU's default)"),
    Key("controller", "objective", Rule("str", choices=tuple(OBJECTIVES)), "",
        "what the command minimises for the torque asked: `current` (the seed's least current) or `loss` (the "
        "least copper + iron + inverter loss; T_cmd and T_max are then shaft torques; docs/least_loss.md)",
        "`current` (the FMU's default, objective 0)"),
    Key("controller", "command_check", Rule("int", lo=0, hi=1), "",
        "1: a command that fails its check on the flux map is replaced by a checked one; 0: sent as the "
        "method made it, counted and logged (to study a method alone; docs/controller.md)",
        "1 (the FMU's default)"),
    Key("controller", "k_u", Rule("real", lo=0.0, hi=1.0, lo_open=True), "1",
        "voltage utilisation: V_max = k_u u_dc / sqrt 3", _meta("k_u")),
    Key("controller", "current_bandwidth", Rule("real", lo=0.0, hi=1e6, lo_open=True),
        "rad/s", "current regulator's closed-loop bandwidth",
        "the FMU's default (its modelDescription start, 2 pi 500 rad/s)"),
    Key("controller", "lut_u_dc", Rule("real", lo=0.0, hi=1e5, lo_open=True),
        "V", "DC voltage the 2-D tables are built at (lut_* methods)",
        _meta("u_dc_V"), acts="method lut_speed"),
    # [thermal]: the machine's thermal network in IpmsmDrive (docs/thermal.md; contract "Thermal")
    Key("thermal", "thermal_model", Rule("bool"), "", "true: the thermal network sets the winding and magnet "
        "temperatures from the losses (they start at the run's temperatures); false: they are the run's, held",
        "false (the FMU's default)"),
    Key("thermal", "T_coolant", OPERATING_TEMPERATURE, "K", "coolant (water-jacket) temperature, held over the run",
        "the FMU's `T_coolant` start", acts="thermal_model"),
    Key("thermal", "T_ambient", OPERATING_TEMPERATURE, "K",
        "ambient air the rotor also rejects heat to, held over the run",
        "the FMU's `T_ambient` start", acts="thermal_model"),
    *(Key("thermal", name, rule, unit, meaning, f"the FMU's `{name}` (docs/thermal.md gives its source)",
          acts="thermal_model") for name, rule, unit, meaning in (
        ("C_stator_yoke", POSITIVE, "J/K", "heat capacity, stator yoke"),
        ("C_stator_tooth", POSITIVE, "J/K", "heat capacity, stator teeth"),
        ("C_winding", POSITIVE, "J/K", "heat capacity, winding"),
        ("C_magnet", POSITIVE, "J/K", "heat capacity, magnets and rotor"),
        ("R_yoke_winding", POSITIVE, "K/W", "resistance stator yoke - winding"),
        ("R_yoke_tooth", POSITIVE, "K/W", "resistance stator yoke - teeth"),
        ("R_tooth_winding", POSITIVE, "K/W", "resistance teeth - winding"),
        ("R_coolant_yoke", POSITIVE, "K/W", "resistance coolant - yoke at 20 degC coolant"),
        ("k_coolant_yoke", Rule("real"), "1/K", "R_coolant_yoke's relative change per kelvin of coolant"),
        *((f"R_{link}_a", NON_NEGATIVE, "K/W", f"{what} resistance a exp(-n / b) + c: a")
          for link, what in LPTN_SPEED_LINKS),
        *((f"R_{link}_b", POSITIVE, "1", f"{what} resistance: b (normalised speed)")
          for link, what in LPTN_SPEED_LINKS),
        *((f"R_{link}_c", POSITIVE, "K/W", f"{what} resistance: c") for link, what in LPTN_SPEED_LINKS),
        ("R_magnet_coolant_0", Rule("real"), "K/W", "magnet - coolant resistance r0 + r_n n + r_c c + r_nc n c: r0"),
        ("R_magnet_coolant_n", Rule("real"), "K/W", "magnet - coolant resistance: r_n"),
        ("R_magnet_coolant_c", Rule("real"), "K/W", "magnet - coolant resistance: r_c (c = coolant / 100 degC)"),
        ("R_magnet_coolant_nc", Rule("real"), "K/W", "magnet - coolant resistance: r_nc"),
        ("k_fe_stator_0", Rule("real"), "1", "stator share of the iron loss k0 + k_n n + k_i i + k_ni n i: k0"),
        ("k_fe_stator_n", Rule("real"), "1", "stator share of the iron loss: k_n"),
        ("k_fe_stator_i", Rule("real"), "1", "stator share of the iron loss: k_i (i = I_rms / I_rms_ref)"),
        ("k_fe_stator_ni", Rule("real"), "1", "stator share of the iron loss: k_ni"),
        ("k_fe_yoke", Rule("real", lo=0.0, hi=1.0), "1", "the yoke's share of the stator's iron loss (the rest: "
         "teeth)"),
        ("w_m_ref", POSITIVE, "rad/s", "speed of n = 1 in the fits"),
        ("I_rms_ref", POSITIVE, "A", "RMS current of i = 1 in the fits"),
        ("T_magnet_estimate_error", Rule("real", lo=-200.0, hi=200.0), "K", "the controller's magnet temperature "
         "is the network's plus this (a drive's estimate)"))),
    # the controller's derating: it acts on the temperatures the controller is given, network or not
    *(Key("thermal", name, rule, "K", meaning, f"the FMU's `{name}` (docs/thermal.md gives its source)")
      for name, rule, meaning in (
        ("T_winding_max", OPERATING_TEMPERATURE, "winding temperature at which the torque limit reaches zero "
         "(above motor.T_winding_ref + derating_margin)"),
        ("T_magnet_max", OPERATING_TEMPERATURE, "magnet temperature at which the torque limit reaches zero (above "
         "motor.T_magnet_ref + derating_margin)"),
        ("derating_margin", POSITIVE, "the torque limit starts to fall this far below T_winding_max and "
         "T_magnet_max"))),
    # [fault]: the inverter stops switching during the run (docs/faults.md; contract "Faults")
    *(Key("fault", name, rule, unit, meaning, "none: one trigger is required", acts="fault")
      for name, rule, unit, meaning in (
        ("t_s", NON_NEGATIVE, "s", "trigger: the fault begins at the first communication point at or after "
         "this time of the cycle (exactly one of t_s, speed_rpm, v_kmh)"),
        ("speed_rpm", POSITIVE, "r/min", "trigger: ... at the first communication point where the motor "
         "speed is at or above this"),
        ("v_kmh", POSITIVE, "km/h", "trigger: ... at the first communication point where the vehicle speed "
         "is at or above this"))),
    Key("fault", "safe_state", Rule("str", choices=tuple(SAFE_STATES)), "", "the state the inverter enters: "
        "`by_speed` (freewheeling below the onset of uncontrolled generation, ASC above: IpmsmDrive's "
        "`safe_state` 0), `freewheel` (1) or `asc` (2)", "`by_speed`", acts="fault"),
    Key("fault", "duration_s", Rule("real", lo=0.0, hi=1e7, lo_open=True), "s", "how long the fault lasts; "
        "then the inverter switches again", "until the end of the run", acts="fault"),
    Key("fault", "i_d_demag", Rule("real", lo=-1e5, hi=0.0, hi_open=True), "A", "the magnets' demagnetisation limit "
        "on i_d (IpmsmDrive's `i_d_demag`; a check limit may compare the fault's peak current with it)",
        "the FMU's `i_d_demag` start (0: no limit)", acts="fault"),
    # [checks]: what `python -m scenarios check` runs and gates on
    Key("checks", "cycles", Rule("strings"), "", "cycles to run: names (WLTC3b, UDDS, HWFET, US06, NEDC) or CSVs "
        "of time_s,speed_mps relative to this file", "[] (nothing to check)", acts="check"),
)

#: the limits `check` compares: summary key -> direction ("max": figure <= limit; "min": >=)
LIMITS = {
    "Wh_per_km_max": ("Wh_per_km", "max"),
    "speed_rmse_mps_max": ("speed_rmse_mps", "max"),
    "torque_rmse_Nm_max": ("torque_rmse_Nm", "max"),
    "torque_error_max_Nm_max": ("torque_error_max_Nm", "max"),
    "time_voltage_limited_pct_max": ("time_voltage_limited_pct", "max"),
    "current_excess_rms_A_max": ("current_excess_rms_A", "max"),
    "regen_curtailed_Wh_max": ("regen_curtailed_Wh", "max"),
    "soc_end_min": ("soc_end", "min"),
    "time_above_top_speed_s_max": ("time_above_top_speed_s", "max"),
    # the fault's figures (a [fault] table; docs/faults.md): a limit on them needs one
    "fault_i_peak_A_max": ("fault_i_peak_A", "max"),
    "fault_demag_margin_A_min": ("fault_demag_margin_A", "min"),
    "fault_braking_torque_Nm_max": ("fault_T_peak_Nm", "max"),
    "fault_charge_Ah_max": ("fault_charge_Ah", "max"),
    "fault_energy_Wh_max": ("fault_energy_Wh", "max"),
    "fault_time_to_zero_current_s_max": ("fault_time_to_zero_current_s", "max"),
}
#: the limits that judge the fault's figures: refused without a [fault] table
FAULT_LIMITS = tuple(k for k in LIMITS if k.startswith("fault_"))
_LIMIT_UNITS = {"Wh_per_km": "Wh/km", "speed_rmse_mps": "m/s", "torque_rmse_Nm": "N m",
                "torque_error_max_Nm": "N m", "time_voltage_limited_pct": "%", "current_excess_rms_A": "A",
                "regen_curtailed_Wh": "Wh", "soc_end": "1", "time_above_top_speed_s": "s", "fault_i_peak_A": "A",
                "fault_demag_margin_A": "A", "fault_T_peak_Nm": "N m", "fault_charge_Ah": "Ah",
                "fault_energy_Wh": "Wh", "fault_time_to_zero_current_s": "s"}
#: a limit's range where its figure has one (a fraction, a percentage); the others: >= 0
_LIMIT_RULES = {"soc_end": Rule("real", lo=0.0, hi=1.0), "time_voltage_limited_pct": Rule("real", lo=0.0, hi=100.0)}
SCHEMA = SCHEMA + tuple(
    Key("checks", name, _LIMIT_RULES.get(s, NON_NEGATIVE), _LIMIT_UNITS[s], f"limit: the summary's `{s}` must be "
        f"{'at most' if d == 'max' else 'at least'} this on every cycle", "no limit", acts="check")
    for name, (s, d) in LIMITS.items())

#: schema key -> the FMU parameter it sets: its rule is narrowed to that parameter's range in the
#: FMUs' model descriptions (the ranges above are the Python models' own: no road vehicle leaves
#: them, and within them every product the vehicle side forms stays finite)
FMU_PARAMETER = {f"motor.{n}": n for n in ("pole_pairs", "R_s", "I_max", "T_magnet_ref", "T_winding_ref", "alpha_cu",
                                         "k_psi_T", "w_m_max", "fe_k_h", "fe_alpha", "fe_k_e", "fe_psi_ref")}
FMU_PARAMETER.update({f"controller.{n}": n for n in ("k_u", "current_bandwidth", "lut_u_dc")})
#: [thermal]: every key is the FMU parameter or input of the same name (contract, "Thermal"); the
#: network's Real parameters are narrowed to their ranges (the Boolean and the inputs keep their rules)
THERMAL_KEYS = tuple(k.name for k in SCHEMA if k.section == "thermal")
#: ... of which the controller's derating, passed whether the network is on or not (it derates
#: on the temperatures the controller is given)
DERATING_KEYS = ("T_winding_max", "T_magnet_max", "derating_margin")
FMU_PARAMETER.update({f"thermal.{n}": n for n in THERMAL_KEYS
                      if n not in ("thermal_model", "T_coolant", "T_ambient") and n in fmu_ranges()})
#: the [inverter] keys: the plant FMU's inverter parameters, by their names
INVERTER_KEYS = tuple(k.name for k in SCHEMA if k.section == "inverter")
FMU_PARAMETER.update({f"inverter.{n}": n for n in INVERTER_KEYS})
SCHEMA = tuple(replace(k, rule=k.rule.within(fmu_ranges().get(FMU_PARAMETER[k.path]))) if k.path in FMU_PARAMETER
               else k for k in SCHEMA)

if "i_d_demag" in fmu_ranges():   # the FMUs' fault parameter (contract, "Faults"), where they have it
    FMU_PARAMETER["fault.i_d_demag"] = "i_d_demag"
    SCHEMA = tuple(replace(k, rule=k.rule.within(fmu_ranges()["i_d_demag"])) if k.path == "fault.i_d_demag" else k
                   for k in SCHEMA)

SECTIONS = ("motor", "inverter", "battery", "vehicle", "controller", "thermal", "fault", "checks")
_BY_PATH = {k.path: k for k in SCHEMA}


# -- what a loaded file is ------------------------------------------------------------------------
@dataclass(frozen=True)
class MotorSpec:
    """The motor: its flux map and the FMUs' parameters (SI; R_s at T_winding_ref)."""

    flux_map: Path
    pole_pairs: int
    R_s: float
    I_max: float
    T_magnet_ref: float
    T_winding_ref: float
    alpha_cu: float
    k_psi_T: float
    J: float
    w_m_max: float | None   # None: the controller FMU's default
    fe_k_h: float
    fe_alpha: float
    fe_k_e: float
    fe_psi_ref: float


#: the controller FMU's own defaults of `method` and `recursion` (its modelDescription)
METHOD_DEFAULT = "ferrari"
RECURSION_DEFAULT = 2
COMMAND_CHECK_DEFAULT = 1
OBJECTIVE_DEFAULT = "current"
#: the controller's loss parameters (contract, "Least-loss control"): the plant's iron-loss
#: parameters and the inverter's, by the same names
MOTOR_LOSS_KEYS = ("fe_k_h", "fe_alpha", "fe_k_e", "fe_psi_ref")


@dataclass(frozen=True)
class ControllerSpec:
    method: str
    recursion: int
    k_u: float                        # V_max = k_u u_dc / sqrt 3
    current_bandwidth: float | None   # rad/s; None: the FMU's default
    lut_u_dc: float                   # V, the 2-D tables' DC voltage
    command_check: int = COMMAND_CHECK_DEFAULT  # 1: failing commands replaced; 0: reported only
    objective: str = OBJECTIVE_DEFAULT            # "current" or "loss" (OBJECTIVES)


@dataclass(frozen=True)
class ThermalSpec:
    """The [thermal] table: every key's value (the FMU's default where the file gives none, read
    from its model description: scenarios.core.fmu_ranges.fmu_starts), by the FMU's names."""

    values: dict = field(default_factory=dict)   # THERMAL_KEYS name -> value
    given: tuple[str, ...] = ()                  # the keys the file gives

    @property
    def on(self) -> bool:
        return bool(self.values["thermal_model"])

    @property
    def T_coolant(self) -> float:
        return self.values["T_coolant"]

    @property
    def T_ambient(self) -> float:
        return self.values["T_ambient"]

    def fmu_params(self) -> dict:
        """IpmsmDrive's network parameters: none with the network off (the FMU as it was without it)."""
        return {k: v for k, v in self.values.items()
                if k not in ("T_coolant", "T_ambient", *DERATING_KEYS)} if self.on else {}

    def derating_params(self) -> dict:
        """The controller's derating parameters the file gives (the rest: the FMU's defaults)."""
        return {k: self.values[k] for k in self.given if k in DERATING_KEYS}

    @classmethod
    def of(cls, given: dict) -> ThermalSpec:
        """The table's values: given, else the FMUs' start values; a key the FMUs do not have
        (an older build) is left out, and refused when given (KeyError naming it)."""
        from scenarios.core.fmu_ranges import fmu_starts
        starts = fmu_starts()
        unknown = [k for k in given if k not in starts]
        if unknown:
            raise KeyError(unknown[0])
        values = {k: given[k] if k in given else starts[k] for k in THERMAL_KEYS if k in starts}
        if not all(k in values for k in ("thermal_model", "T_coolant", "T_ambient")):  # FMUs without the network
            return cls({"thermal_model": False, "T_coolant": math.nan, "T_ambient": math.nan})
        return cls(values, tuple(given))


@dataclass(frozen=True)
class FaultSpec:
    """The [fault] table: when the inverter stops switching (one trigger: a time of the cycle, a
    motor speed or a vehicle speed, whichever the file gives), the safe state it enters, for how
    long (None: until the end) and the magnets' limit (None: the FMU's default)."""

    trigger: str                       # one of FAULT_TRIGGERS
    at: float                          # s, r/min or km/h, by the trigger
    safe_state: str = "by_speed"       # one of SAFE_STATES
    duration_s: float | None = None
    i_d_demag: float | None = None     # A (< 0)

    def value(self, name: str):
        return (self.at if name == self.trigger else None) if name in FAULT_TRIGGERS else getattr(self, name)

    def fmu_params(self) -> dict:
        """IpmsmDrive's parameters of the fault (contract, "Faults")."""
        return {"safe_state": SAFE_STATES[self.safe_state],
                **({} if self.i_d_demag is None else {"i_d_demag": self.i_d_demag})}

    def describe(self) -> str:
        unit = {"t_s": "s", "speed_rpm": "r/min", "v_kmh": "km/h"}[self.trigger]
        return f"fault.{self.trigger} = {self.at:g} {unit}"


@dataclass(frozen=True)
class ChecksSpec:
    cycles: tuple[str, ...] = ()      # names, or CSV paths made absolute
    limits: dict = field(default_factory=dict)   # LIMITS key -> value


@dataclass(frozen=True)
class DriveDescription:
    """A loaded, checked drive description: every value concrete (defaults filled in), SI.
    Picklable: Dask ships it to its workers."""

    name: str
    source: Path | None           # the TOML file
    sha256: str                   # of the file's bytes ("" without a file)
    motor: MotorSpec
    inverter: dict                # INVERTER_KEYS -> value (the plant FMU's parameters)
    battery: BatteryParams
    vehicle: VehicleParams        # J_motor = motor.J
    P_aux: float                  # W, the [vehicle] table's auxiliary load
    controller: ControllerSpec
    checks: ChecksSpec
    assumed: tuple[str, ...] = ()  # the motor's values neither the file nor its map gives, in words
    thermal: ThermalSpec = field(default_factory=lambda: ThermalSpec.of({}))  # [thermal]
    fault: FaultSpec | None = None  # [fault]; None: the inverter never stops

    def value(self, path: str):
        """The value of a schema key ("vehicle.mass", "name", ...) in this description."""
        section, _, name = path.rpartition(".")
        if not section:
            return getattr(self, name)
        if path == "vehicle.P_aux":
            return self.P_aux
        if path == "battery.ocv":
            return str(self.battery.ocv_csv) if self.battery.ocv_fit == "csv" else self.battery.ocv_fit
        if section == "checks":
            return list(self.checks.cycles) if name == "cycles" else self.checks.limits.get(name)
        if section == "thermal":
            return self.thermal.values.get(name)
        if section == "fault":
            return None if self.fault is None else self.fault.value(name)
        if section == "inverter":
            return self.inverter[name]
        return getattr({"motor": self.motor, "battery": self.battery,
                        "vehicle": self.vehicle, "controller": self.controller}[section], name)

    def motor_data(self) -> MotorData:
        """The reference optimum's motor figures (scenarios.runs.simulate.OptimumReference)."""
        m = self.motor
        return MotorData(m.pole_pairs, m.R_s, m.T_winding_ref, m.alpha_cu, m.I_max, self.controller.k_u)

    def controller_params(self, method: str | None = None, recursion: int | None = None,
                          lut_u_dc: float | None = None, lut_T_magnet: float | None = None,
                          command_check: int | None = None, objective: str | None = None) -> dict:
        """The controller FMU's parameters; method/recursion/lut_*/command_check/objective None: the
        drive's. With FMUs that have the least-loss controller, also `objective` and the loss
        parameters (the plant's: the controller predicts P_loss_cmd with either objective)."""
        m, c = self.motor, self.controller
        method = c.method if method is None else method
        if method not in METHODS:
            raise ValueError(f"method {method!r}: one of {', '.join(METHODS)}")
        p = dict(method=METHODS[method], recursion=c.recursion if recursion is None else recursion,
                 flux_map=str(m.flux_map), pole_pairs=m.pole_pairs, R_s=m.R_s, I_max=m.I_max, k_u=c.k_u,
                 T_magnet_ref=m.T_magnet_ref, k_psi_T=m.k_psi_T, T_winding_ref=m.T_winding_ref, alpha_cu=m.alpha_cu,
                 lut_u_dc=c.lut_u_dc if lut_u_dc is None else lut_u_dc,
                 lut_T_magnet=m.T_magnet_ref if lut_T_magnet is None else lut_T_magnet,
                 command_check=c.command_check if command_check is None else command_check)
        p.update(self.thermal.derating_params())
        objective = c.objective if objective is None else objective
        if objective not in OBJECTIVES:
            raise ValueError(f"objective {objective!r}: one of {', '.join(OBJECTIVES)}")
        if controller_has_objective():
            p.update(objective=OBJECTIVES[objective], **self.loss_params())
        elif objective != OBJECTIVE_DEFAULT:
            raise ValueError(f"objective {objective!r}: the built FMUs have no `objective` parameter (rebuild them)")
        # the keys without a value of their own leave the FMU's default (its modelDescription start)
        if m.w_m_max is not None:
            p["w_m_max"] = m.w_m_max
        if c.current_bandwidth is not None:
            p["current_bandwidth"] = c.current_bandwidth
        return p

    def loss_params(self) -> dict:
        """The loss models' parameters, by the FMUs' names: the iron loss's and the inverter's
        (the plant computes the losses with them; the least-loss controller predicts them)."""
        return {**{k: getattr(self.motor, k) for k in MOTOR_LOSS_KEYS}, **self.inverter}

    def plant_params(self) -> dict:
        """The plant FMU's parameters: the motor's (I_max: where it requires the map to be legal)
        and the inverter's (the plant computes its loss)."""
        m = self.motor
        return dict(flux_map=str(m.flux_map), pole_pairs=m.pole_pairs, R_s=m.R_s, I_max=m.I_max,
                    T_winding_ref=m.T_winding_ref,
                    alpha_cu=m.alpha_cu, k_psi_T=m.k_psi_T, T_magnet_ref=m.T_magnet_ref, fe_k_h=m.fe_k_h,
                    fe_alpha=m.fe_alpha, fe_k_e=m.fe_k_e, fe_psi_ref=m.fe_psi_ref, **self.inverter)


def inverter_defaults() -> dict:
    """The [inverter] keys' defaults: the plant FMU's start values (plant/modelDescription.xml,
    generated from the C++ table: the one place they are written)."""
    starts = read_starts(PLANT_DESCRIPTION)
    return {k: starts[k] for k in INVERTER_KEYS}


# -- the loader -----------------------------------------------------------------------------------
#: a flux map's metadata key -> the schema key whose default it gives and whose rule its value
#: obeys: the one table (scenarios.maps.metadata), each key's parameter by its schema name
METADATA_RULE = {k.key: next(f"{s}.{k.parameter}" for s in ("motor", "controller") if f"{s}.{k.parameter}" in _BY_PATH)
                 for k in metadata_keys().values()}

#: a hook for FEM exports: path -> a contract CSV (default: scenarios.maps.importer.contract_csv)
MapResolver = Callable[[Path], Path]


def _map_resolver() -> MapResolver:
    from scenarios.maps.importer import contract_csv  # FEM exports (SyR-e, Motor-CAD, PLECS) to the contract
    return contract_csv


def _nearest(name: str, known) -> str:
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def _read_toml(path: Path) -> tuple[dict, bytes]:
    try:
        return load_toml(path, "drive description (TOML)")
    except DriveDescriptionError:
        raise
    except InputError as e:
        raise DriveDescriptionError(e.file, e.key, e.expected) from None


def _check_keys(path: Path, doc: dict) -> None:
    """Unknown sections and keys, and values of the wrong kind or range: errors."""
    for top, value in doc.items():
        if top in SECTIONS:
            if not isinstance(value, dict):
                raise DriveDescriptionError(path, top, "a table [" + top + "]")
            for name, v in value.items():
                kp = f"{top}.{name}"
                if kp not in _BY_PATH:
                    known = [k.path for k in SCHEMA if k.section == top]
                    raise DriveDescriptionError(path, kp, "a known key: one of " + ", ".join(known) +
                                                _nearest(kp, known))
                bad = _BY_PATH[kp].rule.check(v)
                if bad:
                    raise DriveDescriptionError(path, kp, bad + ("" if "got" in bad else f", got {v!r}") +
                                                _celsius_hint(_BY_PATH[kp], v))
        elif top in _BY_PATH:
            bad = _BY_PATH[top].rule.check(value)
            if bad:
                raise DriveDescriptionError(path, top, bad + f", got {value!r}")
        else:
            known = [*(k.path for k in SCHEMA if not k.section), *SECTIONS]
            raise DriveDescriptionError(path, top, "a known key or table: one of " + ", ".join(known) +
                                        _nearest(top, known))


def _celsius_hint(key: Key, value) -> str:
    """For a temperature in K refused where value + 273.15 K would do: the likely mistake."""
    if key.unit != "K" or key.rule.kind != "real" or isinstance(value, bool) or not isinstance(value, (int, float)):
        return ""
    if not _finite(value) or key.rule.check(value + ZERO_CELSIUS_K) is not None:
        return ""
    return f" (kelvin: {value:g} K is {value - ZERO_CELSIUS_K:g} degC; {value:g} degC is {value + ZERO_CELSIUS_K:g} K)"


def _relative(path: Path, value: str, key: str = "(path)") -> Path:
    """`value` relative to the file's folder (~ expanded), resolved; a path that cannot be
    (an unknown user, a symlink loop, a NUL): DriveDescriptionError naming the key."""
    try:
        p = Path(value).expanduser()
        # located: the shipped drives' paths into the repository (the default map) resolve in a wheel too
        return located(p.resolve() if p.is_absolute() else (path.parent / p).resolve())
    except (RuntimeError, OSError, ValueError) as e:
        raise DriveDescriptionError(path, key, f"a path that resolves ({e})") from None


def _is_file(p: Path) -> bool:
    try:
        return p.is_file()
    except (OSError, ValueError):
        return False


def _load_map(path: Path, value: str, resolve: MapResolver) -> tuple[Path, FluxMap]:
    map_path = _relative(path, value, "motor.flux_map")
    if not _is_file(map_path):
        raise DriveDescriptionError(path, "motor.flux_map", f"an existing flux-map file, {map_path} is not one")
    try:
        csv_path = Path(resolve(map_path))
        return csv_path, read_flux_map(csv_path)
    except DriveDescriptionError:
        raise
    except Exception as e:  # the readers' own words: which file, which line or field
        raise DriveDescriptionError(path, "motor.flux_map", f"a readable flux map ({e})") from None


def _cycle_entry(path: Path, name: str) -> str:
    """A standard cycle's name stays; anything else is a CSV relative to the file."""
    from scenarios.vehicle.cycles import STANDARD_CYCLES
    if name.lower() in {n.lower() for n in STANDARD_CYCLES}:
        return name
    p = _relative(path, name, "checks.cycles")
    if not _is_file(p):
        raise DriveDescriptionError(path, "checks.cycles", f"a standard cycle ({', '.join(STANDARD_CYCLES)}) or an "
                                    f"existing CSV of time_s,speed_mps; {name!r} is neither")
    return str(p)


def load_drive(path: str | Path | None = None, resolve_map: MapResolver | None = None) -> DriveDescription:
    """Read and check a drive description (None: scenarios/drives/default.toml). Raises
    DriveDescriptionError (file, key, expectation) for anything the schema does not allow."""
    try:
        path = Path(DEFAULT_DRIVE if path is None else path).expanduser().resolve()
    except (RuntimeError, OSError, ValueError) as e:
        raise DriveDescriptionError(path, "(file)", f"a path that resolves ({e})") from None
    doc, raw = _read_toml(path)
    _check_keys(path, doc)
    sec = {s: doc.get(s, {}) for s in SECTIONS}
    motor, controller, assumed = _load_machine(path, sec["motor"], sec["controller"], resolve_map or _map_resolver())
    vehicle, P_aux = _load_vehicle(sec["vehicle"], motor)
    return DriveDescription(name=doc.get("name", path.stem), source=path, sha256=hashlib.sha256(raw).hexdigest(),
                            motor=motor, inverter=_load_inverter(sec["inverter"]),
                            battery=_load_battery(path, sec["battery"]), vehicle=vehicle, P_aux=P_aux,
                            controller=controller, checks=_load_checks(path, sec["checks"], motor),
                            assumed=tuple(assumed), thermal=_load_thermal(path, sec["thermal"], motor),
                            fault=_load_fault(path, sec["fault"], sec["checks"]))


def _load_machine(path: Path, given: dict, c: dict, resolve: MapResolver) -> tuple[MotorSpec, ControllerSpec, list]:
    """[motor] and [controller]: each key the file gives, else its flux map's metadata (the
    default motor's where the map has none, an assumption named); the map's values obey the file's
    rules."""
    if "flux_map" not in given:
        raise DriveDescriptionError(path, "motor.flux_map", "a flux-map file: the one key every drive must give")
    map_path, fmap = _load_map(path, given["flux_map"], resolve)
    from_file = {}
    for key in METADATA_RULE.values():
        section, name = key.split(".")
        if name in {"motor": given, "controller": c}[section]:
            from_file[name] = {"motor": given, "controller": c}[section][name]
    try:
        values, assumed = machine_values(fmap, from_file)
        J = from_file["J"] if "J" in from_file else fmap.number("J_kg_m2", VehicleParams().J_motor)
    except (KeyError, ValueError, OverflowError) as e:
        raise DriveDescriptionError(path, "motor", f"values in the file or numbers in the map's metadata ({e})") \
            from None
    if "J" not in from_file and "J_kg_m2" not in fmap.metadata and map_path != DEFAULT_MAP.resolve():
        assumed.append(f"J = {J:.4g} kg m^2: the default motor's rotor (no `J_kg_m2` in the map's metadata)")
    real = {k: (v if k == "pole_pairs" or v is None else float(v)) for k, v in values.items()}
    motor = MotorSpec(flux_map=map_path, J=float(J), **{f.name: real[f.name] for f in fields(MotorSpec)
                                                        if f.name not in ("flux_map", "J")})
    controller = ControllerSpec(
        method=c.get("method", METHOD_DEFAULT), recursion=c.get("recursion", RECURSION_DEFAULT),
        command_check=c.get("command_check", COMMAND_CHECK_DEFAULT), objective=c.get("objective", OBJECTIVE_DEFAULT),
        k_u=real["k_u"], current_bandwidth=float(c["current_bandwidth"]) if "current_bandwidth" in c else None,
        lut_u_dc=real["lut_u_dc"])
    if controller.objective != OBJECTIVE_DEFAULT and not controller_has_objective():
        raise DriveDescriptionError(path, "controller.objective", "a value the built FMUs have: rebuild them (their "
                                    "model descriptions have no `objective` parameter)")
    spec = {"motor": motor, "controller": controller}
    for key in METADATA_RULE.values():   # values from the map obey the same rules as the file's
        section, name = key.split(".")
        value = getattr(spec[section], name)
        bad = None if value is None else _BY_PATH[key].rule.check(value)
        if bad:
            raise DriveDescriptionError(path, key, f"{bad} (from the file or the map's metadata)")
    return motor, controller, assumed


def _load_inverter(given: dict) -> dict:
    return {**inverter_defaults(), **{k: float(v) for k, v in given.items()}}


def _load_battery(path: Path, given: dict) -> BatteryParams:
    b = dict(given)
    ocv = b.pop("ocv", None)
    battery = replace(BatteryParams(), **{k: (v if k in ("n_series", "n_parallel") else float(v))
                                          for k, v in b.items()})
    if ocv is not None:
        if ocv in OCV_FITS:
            battery = replace(battery, ocv_fit=ocv)
        else:
            csv_path = _relative(path, ocv, "battery.ocv")
            if not _is_file(csv_path):
                raise DriveDescriptionError(path, "battery.ocv", f"a shipped fit ({', '.join(OCV_FITS)}) or an "
                                            f"existing CSV of soc,ocv_cell_V; {ocv!r} is neither")
            battery = replace(battery, ocv_fit="csv", ocv_csv=csv_path)
    try:
        from scenarios.vehicle.battery import Ocv
        Ocv(battery)
    except Exception as e:  # the reader's own words (a short or huge row, a negative voltage)
        raise DriveDescriptionError(path, "battery.ocv", f"a usable OCV curve ({e})") from None
    return battery


def _load_vehicle(given: dict, motor: MotorSpec) -> tuple[VehicleParams, float]:
    v = dict(given)
    P_aux = float(v.pop("P_aux", P_AUX_DEFAULT))
    return replace(VehicleParams(), J_motor=motor.J, **{k: float(x) for k, x in v.items()}), P_aux


#: [thermal]'s temperature limits and the motor's reference each must lie above, by more than
#: derating_margin (a limit at or below it can only be meant in degC: the machine would be
#: derated to nothing at its reference)
LIMIT_ABOVE_REFERENCE = {"T_winding_max": "T_winding_ref", "T_magnet_max": "T_magnet_ref"}


def _load_thermal(path: Path, given: dict, motor: MotorSpec) -> ThermalSpec:
    try:
        thermal = ThermalSpec.of({k: (v if k == "thermal_model" else float(v)) for k, v in given.items()})
    except KeyError as e:
        raise DriveDescriptionError(path, f"thermal.{e.args[0]}", "a parameter the built FMUs have: rebuild them "
                                    "(their model descriptions have no such variable)") from None
    _check_derating(path, motor, thermal)
    return thermal


def _load_checks(path: Path, ch: dict, motor: MotorSpec) -> ChecksSpec:
    if "time_above_top_speed_s_max" in ch and motor.w_m_max is None:  # a limit nothing could measure
        raise DriveDescriptionError(path, "checks.time_above_top_speed_s_max",
                                    "a top speed to judge it by: `motor.w_m_max` or `w_m_max_rad_s` in the map's "
                                    "metadata")
    return ChecksSpec(cycles=tuple(_cycle_entry(path, n) for n in ch.get("cycles", [])),
                      limits={k: float(x) for k, x in ch.items() if k in LIMITS})


def _load_fault(path: Path, table: dict, ch: dict) -> FaultSpec | None:
    """[fault] (its values already checked by the schema): exactly one trigger; a [checks] limit on
    the fault's figures needs the table (else it could judge nothing)."""
    if not table:
        for name in FAULT_LIMITS:
            if name in ch:
                raise DriveDescriptionError(path, f"checks.{name}", "a [fault] table: this limit judges the figures "
                                            "of the fault it describes (docs/faults.md)")
        return None
    given = [k for k in FAULT_TRIGGERS if k in table]
    if len(given) != 1:
        key = "fault" if not given else f"fault.{given[1]}"
        raise DriveDescriptionError(path, key, "exactly one trigger: " + ", ".join(f"fault.{k}" for k in FAULT_TRIGGERS)
                                    + (f" (got {', '.join(given)})" if given else " (none given)"))
    return FaultSpec(trigger=given[0], at=float(table[given[0]]), safe_state=table.get("safe_state", "by_speed"),
                     duration_s=float(table["duration_s"]) if "duration_s" in table else None,
                     i_d_demag=float(table["i_d_demag"]) if "i_d_demag" in table else None)


def _check_derating(path: Path, motor: MotorSpec, thermal: ThermalSpec) -> None:
    """The derating's maxima above the temperatures the machine's data hold at, by more than the
    margin: a maximum at or below its reference (180 for 180 degC read as 180 K) would derate a
    machine at its reference to zero torque, a car that never moves."""
    margin = thermal.values.get("derating_margin")
    for name, ref_key in LIMIT_ABOVE_REFERENCE.items():
        T_max, ref = thermal.values.get(name), getattr(motor, ref_key)
        if T_max is None or margin is None:
            continue  # FMUs without the derating
        if not T_max - margin > ref:
            hint = (f"; {T_max:g} K is {T_max - ZERO_CELSIUS_K:g} degC: did you mean {T_max + ZERO_CELSIUS_K:g} K?"
                    if T_max + ZERO_CELSIUS_K - margin > ref else "")
            key = (f"thermal.{name}" if name in thermal.given else "thermal.derating_margin"
                   if "derating_margin" in thermal.given else f"motor.{ref_key}")
            raise DriveDescriptionError(path, key,
                                        f"a temperature in K above motor.{ref_key} + thermal.derating_margin = "
                                        f"{ref:g} + {margin:g} K, got {T_max:g} K{hint}")


def check_metadata_rules(metadata: dict, file: str | Path) -> None:
    """Each contract key of a map's metadata (key -> its text, or a number an importer made) by
    the metadata rule (scenarios.maps.metadata) and the schema's rule of the key it gives the
    default of, as a drive description's value would be: InputError naming `file` and the key."""
    for meta, key in METADATA_RULE.items():
        if meta not in metadata:
            continue
        text, rule = str(metadata[meta]), _BY_PATH[key].rule
        try:
            value = metadata_value(meta, text)
        except MetadataError as e:
            raise InputError(file, meta, f"{e.expected} ({rule.describe()}), got {e.text[:80]!r}") from None
        bad = rule.check(value)
        if bad:
            raise InputError(file, meta, bad + ("" if "got" in bad else f", got {text[:80]!r}"))


def check_map_machine(map_file: str | Path, u_dc: float | None = None, I_max: float | None = None) -> None:
    """A map's own machine, for `map show FILE` without --drive: each number of its
    `# key: value` metadata obeys the schema's rule of the key it sets, as a drive description's
    would (InputError naming the map file and the metadata key), and the command line's --u-dc
    and --I-max theirs (naming the option). The current limit must also be one the map's grid
    resolves (scenarios.maps.machine.grid_resolution)."""
    from scenarios.maps.machine import grid_resolution
    for value, option, key in ((u_dc, "--u-dc", "controller.lut_u_dc"), (I_max, "--I-max", "motor.I_max")):
        bad = None if value is None else _BY_PATH[key].rule.check(value)
        if bad:
            raise InputError("(command line)", option, bad + ("" if "got" in bad else f", got {value!r}"))
    path = Path(map_file)
    try:
        fmap = read_flux_map(_map_resolver()(path))
    except (InputError, MapImportError):
        raise
    except Exception as e:  # the readers' own words: which file, which line or field
        raise InputError(path, "(file)", f"a readable flux map ({e})") from None
    check_metadata_rules(fmap.metadata, path)
    limit = I_max if I_max is not None else (fmap.number("I_max_A") if "I_max_A" in fmap.metadata else None)
    if limit is not None and limit < grid_resolution(fmap):
        where = ("(command line)", "--I-max") if I_max is not None else (path, "I_max_A")
        raise InputError(*where, f"a current limit the map's grid resolves: at least {grid_resolution(fmap):g} A "
                         f"(the grid's nearest nodes to zero current), got {limit!r}")


def schema_markdown() -> str:
    """The schema as a Markdown table with the default EV's values (docs/drives.md holds it; a
    test keeps the two equal)."""
    d = load_drive()
    rows = ["| key | unit | allowed | default: from | default EV | meaning |", "|---|---|---|---|---|---|"]
    for k in SCHEMA:
        v = d.value(k.path) if k.path != "motor.flux_map" else DEFAULT_MAP.relative_to(ROOT).as_posix()
        v = "—" if v is None or v == [] else (f"{v:.6g}" if isinstance(v, float) else
                                             str(v).lower() if isinstance(v, bool) else str(v))
        rows.append(f"| `{k.path}` | {k.unit} | {k.rule.describe()} | {k.default} | {v} | {k.meaning} |")
    return "\n".join(rows)


def known_fields() -> dict[str, tuple[str, ...]]:
    """Section -> its key names (for tools that build descriptions)."""
    return {s: tuple(k.name for k in SCHEMA if k.section == s) for s in ("", *SECTIONS)}


__all__ = ["DEFAULT_DRIVE", "DRIVES_DIR", "FAULT_LIMITS", "FAULT_TRIGGERS", "INVERTER_KEYS", "LIMITS", "METHODS",
           "OBJECTIVES", "SAFE_STATES", "SCHEMA", "ChecksSpec", "ControllerSpec", "DriveDescription",
           "DriveDescriptionError", "FaultSpec", "Key", "MotorSpec", "Rule", "ThermalSpec",
           "inverter_defaults", "load_drive", "schema_markdown"]
