"""The scenarios on the IpmsmDrive FMU (`--backend drive`: the vehicle side at 10 ms, one
fmi2DoStep of the drive per vehicle step through plain fmpy) against the two FMUs coupled at
100 us by the native and the fmpy masters: the same energies (within 0.1 %) and torque errors.
A busy segment in the default run; the full WLTC behind the `slow` marker. On a 80 s segment
(WLTC3b 1480-1560 s) the three agree to the printed 1e-6 Wh and 1e-6 N.m."""
from __future__ import annotations

import pytest

from scenarios.runs.simulate import RunSpec, simulate
from scenarios.vehicle.cycles import load_cycle, segment

from conftest import fmu_path

ENERGIES = ("energy_battery_Wh", "motor_electric_Wh", "shaft_Wh", "copper_loss_Wh", "iron_loss_Wh",
            "inverter_loss_Wh")
TORQUE = ("torque_rmse_Nm", "torque_error_max_Nm")


def _runs(cycle, backends):
    fmus = (fmu_path("IpmsmController"), fmu_path("IpmsmPlant"))
    fmu_path("IpmsmDrive")
    return {b: simulate(cycle, RunSpec(backend=b), fmus=fmus, progress=False).to_dict() for b in backends}


def _agree(runs):
    ref = runs["native"] if "native" in runs else runs["fmpy"]
    for b, s in runs.items():
        print(f"\n[{b}] {s['energy_battery_Wh']:.6f} Wh battery, torque RMSE {s['torque_rmse_Nm']:.6f} N.m, "
              f"max {s['torque_error_max_Nm']:.6f} N.m, {s['wall_s']:.1f} s wall")
        for k in ENERGIES:
            assert s[k] == pytest.approx(ref[k], rel=1e-3), (b, k, s[k], ref[k])
        for k in TORQUE:
            assert s[k] == pytest.approx(ref[k], rel=1e-3, abs=1e-6), (b, k, s[k], ref[k])
        assert s["distance_km"] == pytest.approx(ref["distance_km"], rel=1e-6)


def test_a_busy_segment_on_the_drive_and_the_native_master():
    """(The fmpy master makes the same calls as the native one, bit for bit: test_master.py.)"""
    seg = segment(load_cycle("WLTC3b"), 1480, 1510)
    _agree(_runs(seg, ("native", "drive")))


@pytest.mark.slow
def test_full_wltc_on_the_three_backends():
    _agree(_runs("WLTC3b", ("native", "fmpy", "drive")))
