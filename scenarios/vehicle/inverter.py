"""Traction-inverter losses: a two-level, three-phase IGBT bridge with anti-parallel diodes,
sinusoidal phase currents of peak I, continuous PWM at f_sw (every leg switches every period).

Conduction, each device as a threshold voltage plus a slope resistance (V = V0 + r i), averaged
over the fundamental period and summed over the three legs:

    P_cond = (3/pi)(V_T0 + V_D0) I  +  (3/4)(r_T + r_D) I^2  +  (V_T0 - V_D0) P_ac / u_dc

In each leg the phase current is always carried by exactly one device (IGBT or the opposite
diode); with equal IGBT and diode characteristics that gives the first two terms whatever the
modulation. The share between IGBT and diode depends on the modulation index and power
factor; its effect on the threshold-voltage term is exactly (V_T0 - V_D0) times the mean DC
current P_ac / u_dc, for any modulation (sine or space vector), because the legs' mean
duty-weighted currents sum to it. The matching slope-resistance term, (r_T - r_D) times a
modulation-dependent factor, is left out: with the default values it is < 1 % of the loss.

Switching, the datasheet energies scaled linearly with current and with DC voltage to the
power k_v, each leg hard-switching |i| once per period (turn-on, turn-off, diode recovery):

    P_sw = (6/pi) f_sw (E_on + E_off + E_rec) (I / I_ref) (u_dc / V_ref)^k_v

Every term is linear in I, I^2 or P_ac, so averaging them over a vehicle step is exact with
the step means of |i|, |i|^2 and P_elec (what the co-simulation returns).

Not modelled: junction-temperature dependence (values at 150 C, a hot-running inverter),
dead time, gate-drive and control-board power (counted in the auxiliary load), DC-link
capacitor and busbar losses, discontinuous PWM (which would save ~1/3 of P_sw).
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class InverterParams:
    """Datasheet-class values of a 750 V / 820 A automotive IGBT six-pack (Infineon HybridPACK
    Drive FS820R08A6P2B class, EDT2 IGBT, the module of many 100-150 kW EV inverters), typical
    at T_vj = 150 C; V0 and r from straight lines through the output characteristic between
    ~1/4 and full nominal current. Rounded; see docs/vehicle.md for their status."""

    V_T0: float = 0.70      # V, IGBT threshold voltage          (V_CE,sat ~ 1.2 V at 820 A)
    r_T: float = 0.60e-3    # ohm, IGBT slope resistance
    V_D0: float = 0.80      # V, diode threshold voltage         (V_F ~ 1.37 V at 820 A)
    r_D: float = 0.70e-3    # ohm, diode slope resistance
    E_on: float = 28e-3     # J per turn-on   at I_ref, V_ref
    E_off: float = 42e-3    # J per turn-off  at I_ref, V_ref
    E_rec: float = 18e-3    # J per diode reverse recovery at I_ref, V_ref
    I_ref: float = 820.0    # A, test current of the switching energies (nominal current)
    V_ref: float = 400.0    # V, test DC voltage of the switching energies
    k_v: float = 1.0        # exponent of the voltage scaling (1: linear, the common first cut)
    f_sw: float = 10e3      # Hz: one PWM period per controller sample (100 us), the frequency
    #                         the EDT2 chip set is optimised for (its datasheet's description)


@dataclass
class InverterLoss:
    P_cond: float   # W
    P_sw: float     # W

    @property
    def P(self) -> float:
        return self.P_cond + self.P_sw


def inverter_loss(I_mean: float, I2_mean: float, u_dc: float, f_sw: float | None = None,
                  P_ac_mean: float = 0.0, p: InverterParams | None = None) -> InverterLoss:
    """Loss (W) of the bridge over an interval with the given means of the phase-current peak
    |i| (A), of |i|^2 (A^2), and of the AC power P_ac (W, + motoring; 0 leaves out the
    IGBT/diode share term), at DC voltage u_dc (V). f_sw defaults to p.f_sw; p (None) to InverterParams()."""
    p = p if p is not None else InverterParams()
    if I_mean < 0.0 or I2_mean < 0.0 or u_dc <= 0.0:
        raise ValueError(f"bad operating point: I_mean={I_mean}, I2_mean={I2_mean}, u_dc={u_dc}")
    f = p.f_sw if f_sw is None else f_sw
    P_cond = (3.0 / math.pi) * (p.V_T0 + p.V_D0) * I_mean + 0.75 * (p.r_T + p.r_D) * I2_mean \
        + (p.V_T0 - p.V_D0) * P_ac_mean / u_dc
    P_sw = (6.0 / math.pi) * f * (p.E_on + p.E_off + p.E_rec) * (I_mean / p.I_ref) * (u_dc / p.V_ref) ** p.k_v
    return InverterLoss(P_cond=P_cond, P_sw=P_sw)


def dc_power(P_ac: float, I_mean: float, I2_mean: float, u_dc: float, f_sw: float | None = None,
             p: InverterParams | None = None) -> float:
    """DC-side power (W) of the inverter delivering P_ac (W, + motoring, - regenerating):
    P_dc = P_ac + P_loss in both directions (the loss always comes from the DC side's account)."""
    return P_ac + inverter_loss(I_mean, I2_mean, u_dc, f_sw, P_ac, p).P
