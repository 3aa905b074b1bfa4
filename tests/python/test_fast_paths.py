"""The vehicle loop's fast paths give the numbers of the plain ones, bit for bit (issue 14: the
Python side of a drive run made cheaper without changing any result):

- the battery's OCV lookups, evaluated once per SOC (Ocv.at), against the separate lookups and
  against scipy's PCHIP and a quadrature;
- the battery's cached lookups against the same steps with every cache emptied before each call;
- DriveFmu's fmi2GetReal/fmi2GetInteger on preallocated arrays against fmpy's getters
  by name.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from scenarios.cosim.drive_fmu import DriveFmu, DriveStep
from scenarios.cosim.fmu import get_values
from scenarios.vehicle.battery import OCV_FITS, Battery, BatteryParams

from conftest import fmu_path

#: SOCs at and between the OCV table's points, at its ends and just inside them
SOCS = sorted({*np.linspace(0.0, 1.0, 21).tolist(), *np.linspace(0.0125, 0.9875, 40).tolist(), 1e-9, 1.0 - 1e-9,
               0.5 + 1e-15})


def _bits(x) -> bytes:
    return np.array(x, dtype=float).tobytes()


@pytest.mark.parametrize("fit", list(OCV_FITS))
def test_ocv_at_is_the_three_lookups_and_scipys_pchip(fit):
    ocv = Battery(BatteryParams(ocv_fit=fit)).ocv_fn
    dpchip = ocv.pchip.derivative()
    for s in SOCS:
        v, dv, F = ocv.at(s)
        # the same numbers as the separate lookups
        assert _bits((v, dv, F - ocv.at(0.0)[2])) == _bits((ocv(s), ocv.slope(s), ocv.integral(0.0, s))), s
        # and scipy's: the PCHIP, its derivative, a quadrature of it
        assert v == pytest.approx(float(ocv.pchip(s)), rel=1e-14)
        assert dv == pytest.approx(float(dpchip(s)), rel=1e-12)
        knots = [x for x in ocv.soc_points if 0.0 < x < s]
        assert F == pytest.approx(quad(ocv.pchip, 0.0, s, points=knots or None, limit=200)[0], rel=1e-12, abs=1e-12)
    for bad in (-1e-6, 1.0 + 1e-6):
        with pytest.raises(ValueError, match="outside"):
            ocv.at(bad)


def _empty_caches(b: Battery) -> None:
    b._cache = None
    b._ocv_at = (None, None)


def test_battery_steps_do_not_depend_on_its_cached_lookups():
    """Discharge, charge, the 4.2 V/cell cap near full and the matched-load limit, each call once
    with the caches as the step loop leaves them and once with them emptied: bit-identical."""
    p = BatteryParams(soc0=0.97)
    rng = np.random.default_rng(7)
    powers = [*rng.uniform(-80e3, 90e3, 300), *[-120e3] * 200, 3e6, *rng.uniform(-5e3, 5e3, 100)]
    a, b = Battery(p), Battery(p)
    capped = 0
    for P in powers:
        for dt in (0.01, 0.01, 0.1):
            _empty_caches(b)
            assert _bits((a.max_charge_power(dt), a.max_discharge_power(dt), a.ocv())) == \
                _bits((b.max_charge_power(dt), b.max_discharge_power(dt), b.ocv()))
        _empty_caches(b)
        ra, rb = a.step(float(P), 0.01), b.step(float(P), 0.01)
        assert ra == rb
        capped += ra.P_curtailed > 0.0
        counters = ("soc", "u_rc", "u", "E_terminal", "E_ocv", "E_loss_R0", "E_loss_R1", "E_curtailed", "E_unmet")
        assert _bits([getattr(a, n) for n in counters]) == _bits([getattr(b, n) for n in counters])
    assert capped > 10  # the cap was exercised
    # a state set from outside is seen (the lookups are keyed by the state, not by the last step)
    a.soc, a.u_rc = 0.8, 0.0
    fresh = Battery(p, soc0=0.8)
    assert _bits((a.ocv(), a.max_charge_power(0.01))) == _bits((fresh.ocv(), fresh.max_charge_power(0.01)))


def _inputs(k: int) -> tuple[float, float, float, float, float]:
    """T_ref, w_m, u_dc, T_magnet, T_winding at vehicle step k: motoring, regeneration, field
    weakening at the top speed."""
    return ((220.0, -150.0, 120.0, 0.0)[k // 5 % 4], 100.0 + 45.0 * k, 355.0 - k, 330.0, 350.0)


def test_drive_fmu_outputs_are_the_fmus_outputs_by_name():
    with DriveFmu(fmu_path("IpmsmDrive"), w_m=100.0) as d:
        regions = set()
        for k in range(20):
            s = d.advance(0.01, *_inputs(k))
            assert isinstance(s, DriveStep)
            for name in DriveStep.__dataclass_fields__:
                expected = get_values(d.fmu, d.vars, name)
                assert _bits(getattr(s, name)) == _bits(expected), (k, name)
            regions.add(s.region)
            assert type(s.region) is int
        assert len(regions) > 1   # the region (the one Integer) changed: it is read at every step
