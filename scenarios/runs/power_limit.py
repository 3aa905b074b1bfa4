"""The battery's limit on the drive: the DC power a vehicle step may draw is what the pack can
deliver (its matched-load maximum, Battery.max_discharge_power) less the auxiliary load. A pack
that cannot deliver limits the drive's torque (the car falls behind the trace, visibly); it never
books a shortfall while the drive runs on energy nobody supplied (docs/vehicle.md). (Returned
power beyond what the pack takes is the brake blending's to avoid; what remains is curtailed,
dissipated on the DC side and booked as regen_curtailed_Wh.)

The drive's DC power at a torque command is known only once the step has run, so a step whose
limits the drive could reach is run from a saved FMU state (fmi2GetFMUstate): if its DC power is
above the limit, the state is restored and the torque command scaled back (a bracketing
search on the scale in [0, 1], the DC power being monotone in it) until it is inside. A step the
drive cannot reach at all (the pack gives more than the drive can draw, as for every road car's
pack) runs once, as it always did: the limits change nothing there.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

#: The drive's DC power is at most its AC power 1.5 |u| |i| <= 1.5 (u_dc / sqrt 3) I_max (the
#: regulator's voltage is limited to the inverter's linear range, the command's current to I_max)
#: plus the inverter's loss; this factor on that bound covers the loss (a few per cent of the
#: power, docs/validation.md: the inverter) and a transient current above I_max within a step.
DRIVE_POWER_MARGIN = 2.0
#: trial steps of the torque search at most (each halves the bracket at least: 2^-20 of T_ref)
SEARCH_STEPS = 20
#: the search stops at a DC power within this fraction of the limit (inside it)
SEARCH_TOLERANCE = 1e-3


class BatteryLimitError(RuntimeError):
    """The battery cannot supply even what the drive draws at zero torque (its losses at speed)
    and the auxiliary load: no torque command keeps the DC link's balance; the run stops."""


def drive_power_bound(u_dc: float, I_max: float) -> float:
    """W, a bound on |P_dc| the drive can reach within a step at the DC voltage u_dc (V) and the
    current limit I_max (A)."""
    return DRIVE_POWER_MARGIN * 1.5 * u_dc / math.sqrt(3.0) * I_max


@dataclass(slots=True)
class Limited:
    """A step run within the battery's limits: the drive's record, the torque command it ran at
    (the blending's, or less) and whether the limit took torque away."""

    step: object      # scenarios.cosim.drive_fmu.DriveStep
    T_ref: float      # N m
    limited: bool


def advance_within(drive, dt: float, T_ref: float, w_m: float, u_dc: float, T_magnet: float, T_winding: float,
                   P_max: float, I_max: float, t: float) -> Limited:
    """drive.advance(dt, T_ref, ...) with the step's mean DC power P_dc at most P_max (W): T_ref
    scaled back toward 0 as far as needed. BatteryLimitError when even zero torque draws more
    (t: the step's start, s, for the message)."""
    if P_max >= drive_power_bound(u_dc, I_max):
        return Limited(drive.advance(dt, T_ref, w_m, u_dc, T_magnet, T_winding), T_ref, False)

    def inside(m) -> bool:
        return m.P_dc <= P_max

    saved = drive.save_state()
    try:
        def trial(s: float):
            drive.restore_state(saved)
            return drive.advance(dt, s * T_ref, w_m, u_dc, T_magnet, T_winding)

        m = drive.advance(dt, T_ref, w_m, u_dc, T_magnet, T_winding)
        if inside(m):
            return Limited(m, T_ref, False)
        target = P_max
        zero = trial(0.0)
        if not inside(zero):
            raise BatteryLimitError(
                f"at t = {t:.6g} s the battery can give the drive {P_max:.6g} W, but the "
                f"drive draws {zero.P_dc:.6g} W at zero torque (w_m = {w_m:.6g} rad/s): the pack (battery.R0, "
                f"n_series, vehicle.P_aux) cannot run this drive")
        lo, P_lo, best = 0.0, zero.P_dc, zero   # lo: inside; hi: outside
        hi, P_hi, last = 1.0, m.P_dc, zero
        for _ in range(SEARCH_STEPS):
            # regula falsi on P_dc(s), kept within the bracket's inner 90 % (bisection's pace at worst)
            s = lo + (hi - lo) * (target - P_lo) / (P_hi - P_lo) if P_hi != P_lo else 0.5 * (lo + hi)
            s = min(max(s, lo + 0.05 * (hi - lo)), hi - 0.05 * (hi - lo))
            last = trial(s)
            if not inside(last):
                hi, P_hi = s, last.P_dc
            else:
                lo, P_lo, best = s, last.P_dc, last
                if abs(target - last.P_dc) <= SEARCH_TOLERANCE * abs(target):
                    break
        if last is not best:
            best = trial(lo)  # the same inputs from the same state: the same step
        return Limited(best, lo * T_ref, True)
    finally:
        drive.free_state(saved)
