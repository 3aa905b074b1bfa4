"""The inverter's loss model, the one there is (fmu_src/inverter/inverter_loss.hpp, IpmsmPlant's P_inv,
which IpmsmDrive reads), checked from outside through the plant FMU: at initialisation P_inv is the
loss at the start current (i_q_start: the phase-current peak) and the AC power the voltage inputs
make (P_elec = 1.5 u_q i_q), at u_dc. Against a brute-force average over the fundamental period of
three legs under sine PWM (IGBT/diode conduction weighted by the duty, the switching energy every
PWM period), and for plausible efficiencies of a Si-IGBT traction inverter at 10 kHz.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from scenarios.core.constants import U_DC_NOMINAL_V
from scenarios.cosim.fmu import CosimError, Fmu
from scenarios.drives.description import inverter_defaults

CONDUCTION_OFF = dict(V_T0=0.0, V_D0=0.0, r_T=0.0, r_D=0.0)
SWITCHING_OFF = dict(E_on=0.0, E_off=0.0, E_rec=0.0)


def plant_loss(plant_fmu, I: float, P_ac: float, u_dc: float = U_DC_NOMINAL_V, **inverter) -> float:
    """IpmsmPlant's P_inv (W) at initialisation with |i| = I (A) and P_elec = P_ac (W) at u_dc (V)."""
    u_q = P_ac / (1.5 * I) if I > 0.0 else 0.0
    with Fmu(plant_fmu, i_q_start=I, u_q=u_q, u_dc=u_dc, **inverter) as p:
        P_inv, P_elec = p.get("P_inv", "P_elec")
    assert P_elec == pytest.approx(P_ac, rel=1e-12, abs=1e-9)
    return P_inv


def _brute_force_inverter(I, M, phi, u_dc, p: dict, n=20000):
    """Three legs, sine PWM, averaged over the period: IGBT/diode conduction weighted by the
    duty, switching energy proportional to |i| every PWM period."""
    th = (np.arange(n) + 0.5) / n * 2 * np.pi
    P_cond = P_sw = P_ac = 0.0
    for k in range(3):
        i = I * np.sin(th - 2 * np.pi * k / 3)
        d = 0.5 * (1 + M * np.sin(th - 2 * np.pi * k / 3 + phi))   # upper switch duty
        a = np.abs(i)
        vT, vD = p["V_T0"] + p["r_T"] * a, p["V_D0"] + p["r_D"] * a
        # i > 0: upper IGBT (d) or lower diode (1 - d); i < 0: lower IGBT (1 - d) or upper diode (d)
        P_cond += np.mean(np.where(i > 0, d * vT + (1 - d) * vD, (1 - d) * vT + d * vD) * a)
        P_sw += np.mean(p["f_sw"] * (p["E_on"] + p["E_off"] + p["E_rec"]) * a / p["I_ref"]
                        * (u_dc / p["V_ref"]) ** p["k_v"])
        P_ac += np.mean((2 * d - 1) * u_dc / 2 * i)
    return P_cond, P_sw, P_ac


@pytest.mark.parametrize("I,M,phi", [(200.0, 0.9, 0.5), (400.0, 1.0, 0.2), (80.0, 0.3, 1.2),
                                     (300.0, 0.8, math.pi - 0.4)])
def test_the_plants_loss_against_brute_force(plant_fmu, I, M, phi):
    p = inverter_defaults()
    u_dc = U_DC_NOMINAL_V
    Pc, Ps, Pac = _brute_force_inverter(I, M, phi, u_dc, p)
    assert Pac == pytest.approx(0.75 * u_dc * M * I * math.cos(phi), rel=1e-6)
    P_sw = plant_loss(plant_fmu, I, Pac, u_dc, **CONDUCTION_OFF)
    P_cond = plant_loss(plant_fmu, I, Pac, u_dc, **SWITCHING_OFF)
    assert P_sw == pytest.approx(Ps, rel=1e-6)
    # the left-out (r_T - r_D) share term is below 1 % of the loss
    assert P_cond == pytest.approx(Pc, abs=0.01 * (P_cond + P_sw))


def test_the_plants_loss_is_plausible(plant_fmu):
    # mid load: 40 kW at 200 A peak, 355 V (~114 N m at the base speed): 97-98.5 %
    P = 40e3
    loss = plant_loss(plant_fmu, 200.0, P)
    assert 0.97 < P / (P + loss) < 0.985
    P_sw = plant_loss(plant_fmu, 200.0, P, **CONDUCTION_OFF)
    assert 0.3 < P_sw / loss < 0.7        # conduction and switching of similar size at 10 kHz
    # near peak: 100 kW at 450 A: still above 98 %; light load 3 kW at 30 A: ~97 %
    assert 100e3 / (100e3 + plant_loss(plant_fmu, 450.0, 100e3)) > 0.98
    assert 0.95 < 3e3 / (3e3 + plant_loss(plant_fmu, 30.0, 3e3)) < 0.98
    # regenerating: a loss too (it comes out of the returned power)
    assert plant_loss(plant_fmu, 200.0, -40e3) > 0.0
    # switching loss scales with u_dc (k_v = 1), conduction not
    a = plant_loss(plant_fmu, 100.0, 5e3, 300.0, **CONDUCTION_OFF)
    b = plant_loss(plant_fmu, 100.0, 5e3, 400.0, **CONDUCTION_OFF)
    assert b == pytest.approx(a * 400 / 300, rel=1e-12)
    c = plant_loss(plant_fmu, 100.0, 0.0, 300.0, **SWITCHING_OFF)
    d = plant_loss(plant_fmu, 100.0, 0.0, 400.0, **SWITCHING_OFF)
    assert c == pytest.approx(d, rel=1e-12)
    assert plant_loss(plant_fmu, 0.0, 0.0) == 0.0
    with pytest.raises(CosimError, match="u_dc"):
        plant_loss(plant_fmu, 10.0, 100.0, 0.0)
