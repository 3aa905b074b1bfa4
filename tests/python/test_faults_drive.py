"""IpmsmDrive's fault handling (docs/spec/INTERFACE.md, "Faults"; docs/faults.md): the safe state
chosen by speed or forced, freewheeling to ASC when the speed rises past the onset in the fault,
fmi2OK throughout and a drive that regulates again after the fault clears, i_peak, the
demagnetisation warning once, the DC link's energy in each state, the thermal network heated by
the fault currents, FMU states, and fault = false bit for bit as the FMU before the faults."""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from scenarios.cosim.fmu import Fmu

import fmi2_raw as raw

BASELINE = Path(os.environ.get("IPMSM_BASELINE_FMU_DIR", "/work/coord/baseline_fmu"))
PSI_0, P, U_DC = 0.0780669432093, 4, 355.0
W_LINE = U_DC / (math.sqrt(3) * P * PSI_0)  # rad/s: the line-to-line onset of the default motor


@pytest.fixture(scope="module")
def drive_fmu():
    from conftest import fmu_path
    return fmu_path("IpmsmDrive")


def steps(f, n, h=1e-3, names=("T_e", "i_d", "i_q", "inverter_state", "i_peak", "E_dc", "P_dc")):
    rows = []
    for _ in range(n):
        f.step(f.t, h)
        rows.append(f.get(*names))
    return rows


@pytest.mark.parametrize("safe_state,ratio,expected", [(0, 0.6, 1), (0, 1.3, 2), (1, 1.3, 1), (2, 0.6, 2)])
def test_safe_state_and_restart(drive_fmu, safe_state, ratio, expected):
    w_m = ratio * W_LINE
    with Fmu(drive_fmu, safe_state=safe_state) as f:
        f.set(T_ref=80.0, w_m=w_m)
        before = steps(f, 30)
        assert before[-1][3] == 0 and before[-1][4] == 0.0
        T_before = before[-1][0]
        f.set(fault=True)
        fault = steps(f, 60)
        assert {r[3] for r in fault} == {expected}
        i_abs = [math.hypot(r[1], r[2]) for r in fault]
        assert fault[-1][4] >= max(i_abs) and fault[-1][4] > 0
        if expected == 2:
            assert np.mean([r[0] for r in fault]) * w_m < 0  # ASC brakes
        f.set(fault=False)
        after = steps(f, 60)
        assert after[0][3] == 0
        T_after = np.array([r[0] for r in after])
        I_after = np.array([math.hypot(r[1], r[2]) for r in after])
        print(f"safe_state {safe_state} at {w_m * 30 / math.pi:.0f} r/min: state {expected}, i_peak "
              f"{fault[-1][4]:.0f} A, T_e in the fault {fault[-1][0]:.1f} N.m; after: T_e {T_after[:5].round(1)} .. "
              f"{T_after[-1]:.2f} N.m (before {T_before:.2f}), max |i| {I_after.max():.0f} A")
        assert T_after[-1] == pytest.approx(T_before, rel=1e-3)  # regulates again
        assert I_after.max() <= 1.02 * 500.0  # within I_max (2 % for the regulator's transient)
        assert T_after.max() <= T_before * 1.05 + 1.0  # no torque jump past the command


def test_freewheel_to_asc_when_the_speed_rises(drive_fmu):
    with Fmu(drive_fmu) as f:
        f.set(T_ref=50.0, w_m=0.8 * W_LINE)
        steps(f, 10)
        f.set(fault=True)
        states = []
        for w in np.linspace(0.8, 1.2, 40) * W_LINE:
            f.set(w_m=w)
            states.append(steps(f, 1)[0][3])
        f.set(w_m=0.8 * W_LINE)
        states += [r[3] for r in steps(f, 10)]
    first_asc = states.index(2)
    assert set(states[:first_asc]) == {1} and set(states[first_asc:]) == {2}  # stays ASC in the fault
    w_switch = np.linspace(0.8, 1.2, 40)[first_asc] * W_LINE
    assert W_LINE <= w_switch <= W_LINE * (1 + 0.4 / 39 + 1e-9)


def test_dc_link_energy_in_each_state(drive_fmu):
    """ASC: the DC link gives and receives nothing; freewheeling above the onset: it receives."""
    with Fmu(drive_fmu, safe_state=2) as f:
        f.set(T_ref=0.0, w_m=1.3 * W_LINE, fault=True)
        rows = steps(f, 50)
        assert all(r[6] == 0.0 for r in rows) and rows[-1][5] == 0.0
    with Fmu(drive_fmu, safe_state=1) as f:
        f.set(T_ref=0.0, w_m=1.3 * 2 / math.pi * math.sqrt(3) * W_LINE, fault=True)
        rows = steps(f, 50)
        E_dc, E_mech, E_cu, E_fe, E_inv = f.get("E_dc", "E_mech", "E_cu", "E_fe", "E_inv")
        print(f"freewheeling: E_dc {E_dc:.1f} J (received), E_mech {E_mech:.1f} J, E_cu {E_cu:.2f}, E_fe {E_fe:.2f}, "
              f"E_inv {E_inv:.2f} J, P_dc {rows[-1][6]:.0f} W")
        assert rows[-1][6] < 0 and E_dc < 0 and E_inv > 0 and E_mech < E_dc


def test_demagnetisation_warned_once(fmu_instances):
    inst = fmu_instances("IpmsmDrive", logging_on=True)
    inst.init(i_d_demag=-200.0, safe_state=2)
    inst.set(w_m=1.5 * W_LINE, fault=True)
    for _ in range(3):
        for _ in range(20):
            assert inst.step(1e-3) in (raw.OK, raw.WARNING)
        inst.set(fault=False)
        for _ in range(5):
            assert inst.step(1e-3) in (raw.OK, raw.WARNING)
        inst.set(fault=True)
    warned = [m for s, _, m in inst.log.records if "demagnetisation" in m]
    assert len(warned) == 1, inst.log.text()


def test_safe_state_out_of_range_refused(fmu_instances):
    inst = fmu_instances("IpmsmDrive", logging_on=True)
    assert inst.setup() == raw.OK and inst.enter() == raw.OK
    raw.refused(inst, inst.set_status, "safe_state", 3, match="safe_state")
    assert inst.exit() == raw.OK
    inst.set(fault=True, w_m=800.0)
    for _ in range(5):
        assert inst.step(1e-3) == raw.OK


def test_thermal_network_heats_with_the_fault_currents(drive_fmu):
    theta = {}
    for fault in (False, True):
        with Fmu(drive_fmu, thermal_model=True, safe_state=2) as f:
            f.set(T_ref=0.0, w_m=1.2 * W_LINE, fault=fault)
            steps(f, 200, 1e-2)
            theta[fault] = f.get("theta_winding", "E_cu")
    print(f"after 2 s at {1.2 * W_LINE * 30 / math.pi:.0f} r/min: winding {theta[False][0] - 273.15:.2f} degC "
          f"without the fault, {theta[True][0] - 273.15:.2f} degC in ASC (E_cu {theta[True][1]:.0f} J)")
    assert theta[True][0] > theta[False][0] + 1.0


def test_fmu_state_in_a_fault(fmu_instances):
    inst = fmu_instances("IpmsmDrive")
    inst.init()
    inst.set(T_ref=100.0, w_m=0.9 * W_LINE)
    for _ in range(5):
        assert inst.step(1e-3) == raw.OK
    inst.set(fault=True)
    assert inst.step(1e-3) == raw.OK
    saved, t_saved = inst.serialize(inst.get_state()), inst.t
    names = ("T_e", "i_d", "i_q", "inverter_state", "i_peak", "E_dc")

    def trace():
        out = []
        for w, fault in ((0.9, True), (1.2, True), (1.2, False), (1.0, False)):
            inst.set(w_m=w * W_LINE, fault=fault)
            for _ in range(5):
                assert inst.step(1e-3) == raw.OK
                out.append(inst.get(*names))
        return out

    assert inst.replays(saved, t_saved, trace)


@pytest.mark.skipif(not (BASELINE / "IpmsmDrive.fmu").exists(), reason="no baseline FMU")
def test_no_fault_bit_for_bit_as_the_baseline(drive_fmu):
    def trace(path):
        with Fmu(path) as f:
            names = [v for v, var in f.vars.items() if var.causality == "output" and var.type in ("Real", "Integer")]
            rows, t = [], 0.0
            for k in range(200):
                f.set(T_ref=150.0 * math.sin(k / 30.0), w_m=200.0 + 4.0 * k)
                f.step(t, 1e-3)
                t += 1e-3
                rows.append(f.get(*names))
            return names, np.array(rows, dtype=float)

    names_base, base = trace(BASELINE / "IpmsmDrive.fmu")
    names_now, now = trace(drive_fmu)
    assert base.tobytes() == now[:, [names_now.index(n) for n in names_base]].tobytes()


W_FUNDAMENTAL = 2 * U_DC / (math.pi * P * PSI_0)  # rad/s: the fundamental onset (MATH.md, "Onset and blocking")


@pytest.mark.parametrize("rpm", [50, 300, 1000, 2500, 3000, 4500, 5000, 6000, 6500, 6800, 7100, 8000, 9000, 12000])
def test_freewheeling_starts_from_no_load_at_any_speed(drive_fmu, rpm):
    """A trip from no load (T_ref = 0: the current zero up to rounding, or field weakening's)
    freewheels from the first step:
    blocked with i = 0 exactly below the fundamental onset, conducting above it. Every step fmi2OK
    (Fmu raises on any other status)."""
    w_m = rpm * math.pi / 30
    with Fmu(drive_fmu, safe_state=1) as f:
        f.set(T_ref=0.0, w_m=w_m)
        steps(f, 5, h=10e-3)
        f.set(fault=True)
        fault = steps(f, 10, h=10e-3)
        assert {r[3] for r in fault} == {1}
        I = [math.hypot(r[1], r[2]) for r in fault]
        if w_m < W_FUNDAMENTAL:
            assert I[-1] == 0.0 and fault[-1][6] == 0.0
        else:
            assert I[-1] > 1.0 and fault[-1][6] < 0.0  # the bridge charges the DC link
