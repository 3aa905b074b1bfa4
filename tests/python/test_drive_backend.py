"""The scenarios on the IpmsmDrive FMU (`--backend drive`, the fast path: the vehicle side at 10 ms,
one fmi2DoStep of the drive per vehicle step) against the reference loop (`--backend fmpy`: the two
FMUs coupled at 100 us in Python): the same energies and torque errors to 1e-9. Both make the same
record (a DriveStep), the drive's means from the plant's exact integrals inside, the reference
loop's from the same integrals read after each vehicle step; the inverter loss is linear in the
means, so the C++ per-step loss and the Python one from the means agree to rounding. A busy
segment in the default run; the full WLTC behind the `slow` marker."""
from __future__ import annotations

import pytest

from scenarios.runs.simulate import RunSpec, simulate
from scenarios.vehicle.cycles import load_cycle, segment

from conftest import fmu_path

ENERGIES = ("energy_battery_Wh", "motor_electric_Wh", "shaft_Wh", "copper_loss_Wh", "iron_loss_Wh",
            "inverter_loss_Wh")
TORQUE = ("torque_rmse_Nm", "torque_error_max_Nm", "current_excess_rms_A")


def _runs(cycle, backends):
    fmus = (fmu_path("IpmsmController"), fmu_path("IpmsmPlant"))
    fmu_path("IpmsmDrive")
    return {b: simulate(cycle, RunSpec(backend=b), fmus=fmus, progress=False).to_dict() for b in backends}


def _agree(runs):
    ref = runs["fmpy"]
    for b, s in runs.items():
        print(f"\n[{b}] {s['energy_battery_Wh']:.9f} Wh battery, torque RMSE {s['torque_rmse_Nm']:.9f} N.m, "
              f"max {s['torque_error_max_Nm']:.9f} N.m, {s['wall_s']:.1f} s wall")
        for k in ENERGIES + TORQUE:
            assert s[k] == pytest.approx(ref[k], rel=1e-9, abs=1e-12), (b, k, s[k], ref[k])
        assert s["distance_km"] == pytest.approx(ref["distance_km"], rel=1e-12)


def test_a_busy_segment_on_the_drive_and_the_reference_loop():
    seg = segment(load_cycle("WLTC3b"), 1480, 1510)
    _agree(_runs(seg, ("fmpy", "drive")))


@pytest.mark.slow
def test_full_wltc_on_both_backends():
    _agree(_runs("WLTC3b", ("fmpy", "drive")))
