"""The IpmsmController and IpmsmPlant FMUs coupled by the reference loop (ReferenceDrive,
scenarios/cosim/reference.py, on the coupling description: Jacobi exchange, as a digital drive: the voltage the
controller computes at t_k is applied by the plant over [t_k + h, t_k + 2h]; the controller sees
the plant's currents at t_k) at 100 us on the default map, speed held: torque steps
0 -> 150 N.m -> -100 N.m settle to the commanded torque, with sane regions and currents.
"""
import math

import numpy as np
import pytest

from scenarios.cosim.reference import ReferenceDrive

H = 1e-4
I_MAX = 500.0
RECORDED = ("T_cmd", "region", "T_e", "i_d", "i_q", "T_shaft")


def run(controller_fmu, plant_fmu, rpm, torque, t_end):
    """Rows (t_{k+1}, then RECORDED after the step from t_k: T_e, T_shaft its means)."""
    w_m = rpm * 2 * math.pi / 60
    n = int(round(t_end / H))
    rows = []
    with ReferenceDrive(controller_fmu, plant_fmu, h=H, w_m=w_m) as ref:
        # The controller's outputs after initialisation hold the measured current (a flying start).
        u_d, u_q = ref.get("controller.u_d_ref", "controller.u_q_ref")
        # (Above about 6000 r/min the back-EMF exceeds the inverter's u_dc / sqrt 3: the voltage
        # is limited and field-weakening current flows from the first step.)
        u_hold, u_lim = 4 * w_m * ref.get("plant.psi_d"), 355.0 / math.sqrt(3)
        assert math.hypot(u_d, u_q) == pytest.approx(min(u_hold, u_lim), rel=1e-9)
        for k in range(n):
            s = ref.advance(H, torque(k * H), w_m, 355.0, 293.15, 293.15)
            rows.append([(k + 1) * H] + [getattr(s, name) for name in RECORDED])
    return np.array(rows, dtype=float)


STEPS = [(5e-3, 150.0), (25e-3, -100.0)]  # the first 5 ms: start-up at zero torque


def torque(t):
    value = 0.0
    for start, T in STEPS:
        if t >= start:
            value = T
    return value


# speed (r/min) -> the region the controller must be in for each torque step (MATH.md)
CASES = {1000: (1, 1), 6000: (2, 2), 11000: (4, 4)}


@pytest.mark.parametrize("rpm", list(CASES))
def test_torque_steps_settle(controller_fmu, plant_fmu, rpm):
    r = run(controller_fmu, plant_fmu, rpm, torque, 45e-3)
    t, T_cmd, region, T_e, i_d, i_q = r[:, 0], r[:, 1], r[:, 2], r[:, 3], r[:, 4], r[:, 5]
    assert np.all(np.isfinite(r))
    bounds = [s for s, _ in STEPS] + [t[-1] + H]
    for (start, T), end, expected_region in zip(STEPS, bounds[1:], CASES[rpm]):
        m = (t > start + 1e-9) & (t <= end + 1e-9)
        cmd = T_cmd[m][-1]
        assert np.all(T_cmd[m] == cmd)  # speed held: a constant command
        assert abs(cmd) <= abs(T) + 1e-9 and np.sign(cmd) == np.sign(T)
        if rpm <= 6000:
            assert cmd == T  # reachable there
        outside = np.nonzero(np.abs(T_e[m] - cmd) > 0.01 * abs(cmd))[0]
        settle = (t[m][outside[-1]] - start) if len(outside) else 0.0
        final = abs(T_e[m][-1] - cmd) / abs(cmd)
        overshoot = max(0.0, np.max((T_e[m] - cmd) * np.sign(cmd)) / abs(cmd))
        print(f"{rpm} r/min, step to {T:.0f} N.m (T_cmd {cmd:.2f}): within 1 % after {settle * 1e3:.1f} ms, "
              f"final error {final:.1e}, overshoot {overshoot:.0%}, "
              f"peak |i| {np.hypot(i_d[m], i_q[m]).max():.0f} A, regions {sorted(set(region[m].astype(int)))}")
        # The regulator's flux loop is first order at alpha_c = 2 pi 500 Hz: no overshoot, and
        # within 1 % in about 5 time constants (1.6 ms) plus the one-sample delay.
        assert settle < 3e-3, f"{rpm} r/min: T_e still outside 1 % of {cmd} N.m {settle * 1e3:.1f} ms after the step"
        assert overshoot < 0.01, f"{rpm} r/min: overshoot {overshoot:.1%}"
        assert final < 1e-6
        assert set(region[m].astype(int)) == {expected_region}
        assert np.hypot(i_d[m], i_q[m]).max() < 1.05 * I_MAX
        assert np.hypot(i_d[m][-1], i_q[m][-1]) <= I_MAX * (1 + 1e-6)
    before = (t >= STEPS[0][0] - 1e-3) & (t <= STEPS[0][0])
    print(f"{rpm} r/min, T_ref = 0: |T_e| <= {np.abs(T_e[before]).max():.2f} N.m")
    assert np.abs(T_e[before]).max() < 5.0  # about no torque before the first command
