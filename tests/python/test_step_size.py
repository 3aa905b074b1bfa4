"""The coupled drive (IpmsmController + IpmsmPlant, Jacobi as in test_coupled.py: the voltage
the controller computes at t_k is applied by the plant over [t_k + h, t_k + 2h]) at communication
steps h from 10 us to 1 ms (issue 12, item 5): the controller runs once per step, so its current
loop must be designed for that sample time, one-sample delay and rotation of the dq frame within
a sample (omega h = 5 rad at 12 000 r/min and 1 ms) included.

Criteria (issue 12): after the torque step has settled, the mean torque within 1 % of the
commanded torque T_cmd and its ripple (peak to peak) under 2 % of it. The plant is stepped at
up to 100 us inside each communication step, its voltage held, so that the torque between the
controller's samples is seen too.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from scenarios.fmu import Fmu

T_END = 0.08           # s
T_STEP = 0.01          # s, the torque step (0 before it: start-up)
SETTLED = 0.05         # s, the window [SETTLED, T_END] is judged
PLANT_SUBSTEP = 1e-4   # s, at most
MEAN_TOL = 0.01        # of |T_cmd| (issue 12)
RIPPLE_TOL = 0.02      # peak to peak, of |T_cmd| (issue 12)
I_MAX = 500.0          # A, the default motor's

# (speed r/min, torque command N.m): MTPA, field weakening (voltage limit), deep field weakening
# near MTPV at top speed (the command clamped to T_max there), braking.
CASES = [(1000, 150.0), (6000, 150.0), (11000, 100.0), (4000, -150.0)]


def run(controller_fmu, plant_fmu, h, rpm, T_ref, t_end=T_END, logs=None):
    """Times, T_ref, T_cmd (controller at each step) and the plant's T_e, i_d, i_q at every
    plant substep."""
    w_m = rpm * 2 * math.pi / 60
    n_sub = max(1, int(math.ceil(h / PLANT_SUBSTEP - 1e-9)))
    h_sub = h / n_sub
    ctrl, plant = [], []
    with Fmu(controller_fmu, w_m=w_m, logging=logs is not None) as c, Fmu(plant_fmu, w_m=w_m) as p:
        u_d, u_q = c.get("u_d_ref", "u_q_ref")
        for k in range(int(round(t_end / h))):
            t = k * h
            T = T_ref if t >= T_STEP - 1e-12 else 0.0
            i_d, i_q = p.get("i_d", "i_q")
            c.set(T_ref=T, w_m=w_m, i_d=i_d, i_q=i_q)
            p.set(u_d=u_d, u_q=u_q, w_m=w_m)
            for j in range(n_sub):
                p.step(t + j * h_sub, h_sub)
                plant.append((t + (j + 1) * h_sub, *p.get("T_e", "i_d", "i_q")))
            c.step(t, h)
            u_d, u_q = c.get("u_d_ref", "u_q_ref")
            ctrl.append((t + h, T, c.get("T_cmd")))
    return np.array(ctrl), np.array(plant)


def judge(ctrl, plant):
    """Mean torque error and ripple over the settled window, relative to |T_cmd|; peak current."""
    cmd = ctrl[-1, 2]
    assert np.all(ctrl[ctrl[:, 0] > SETTLED, 2] == cmd), "the command must be constant (inputs held)"
    m = plant[:, 0] > SETTLED + 1e-12
    T_e = plant[m, 1]
    return dict(T_cmd=cmd, mean=(T_e.mean() - cmd) / abs(cmd), ripple=(T_e.max() - T_e.min()) / abs(cmd),
                I_peak=float(np.hypot(plant[:, 2], plant[:, 3]).max()))


def _check(controller_fmu, plant_fmu, h, rpm, T_ref):
    ctrl, plant = run(controller_fmu, plant_fmu, h, rpm, T_ref)
    assert np.all(np.isfinite(plant)) and np.all(np.isfinite(ctrl))
    r = judge(ctrl, plant)
    print(f"\nh = {h * 1e3:g} ms, {rpm} r/min, T_ref {T_ref:g} N.m: T_cmd {r['T_cmd']:.2f} N.m, mean error "
          f"{r['mean']:+.3%}, ripple {r['ripple']:.3%}, peak |i| {r['I_peak']:.0f} A")
    assert abs(r["mean"]) <= MEAN_TOL, f"mean torque {r['mean']:+.2%} off T_cmd = {r['T_cmd']:.2f} N.m"
    assert r["ripple"] <= RIPPLE_TOL, f"torque ripple {r['ripple']:.2%} of T_cmd = {r['T_cmd']:.2f} N.m"
    assert r["I_peak"] <= 1.05 * I_MAX, f"peak current {r['I_peak']:.0f} A"


@pytest.mark.parametrize("rpm,T_ref", CASES, ids=[f"{r}rpm_{T:g}Nm" for r, T in CASES])
@pytest.mark.parametrize("h", [1e-4, 4e-4, 1e-3], ids=["100us", "400us", "1ms"])
def test_coupled_drive_at_any_step(controller_fmu, plant_fmu, h, rpm, T_ref):
    _check(controller_fmu, plant_fmu, h, rpm, T_ref)


@pytest.mark.slow
@pytest.mark.parametrize("rpm,T_ref", CASES, ids=[f"{r}rpm_{T:g}Nm" for r, T in CASES])
@pytest.mark.parametrize("h", [1e-5, 2e-4, 7e-4], ids=["10us", "200us", "700us"])
def test_coupled_drive_at_more_steps(controller_fmu, plant_fmu, h, rpm, T_ref):
    _check(controller_fmu, plant_fmu, h, rpm, T_ref)
