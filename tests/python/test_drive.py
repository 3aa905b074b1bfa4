"""The IpmsmDrive FMU (issue 14) against the two FMUs coupled by the reference loop at 100 us.

The drive runs the controller's and the plant's models through the same coupling description, so
at any communication step (100 us, 1 ms, 10 ms) its step means and integrals must equal the
reference loop's (scenarios/cosim/reference.py) records of 1 ms, up to rounding (the inverter's
loss in both: the plant's, per 100 us). The run has torque steps, regeneration and a speed ramp
through every region.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Error, fmi2OK

from scenarios.cosim.drive_fmu import DriveFmu
from scenarios.cosim.reference import ReferenceDrive
from scenarios.maps.flux_map import linear_flux_map, write_flux_map

from conftest import fmu_path

H = 1e-4  # s, sample_time and the master's step
BLOCK = 0.01  # s, the inputs change only at multiples of it (the coarsest step tested)
U_DC, T_MAGNET, T_WINDING = 355.0, 353.15, 373.15


@dataclass(frozen=True)
class DriveInputs:
    T_ref: float      # N.m
    w_m: float        # rad/s
    u_dc: float       # V
    T_magnet: float   # K
    T_winding: float  # K


def profile() -> list[DriveInputs]:
    """Inputs per 10 ms block over 1.6 s: w_m ramps 50 -> 1150 rad/s (MTPA, the voltage limit,
    MTPV at the top), T_ref steps between motoring and regeneration, and ends at 0 N.m."""
    blocks = []
    n = 160
    for b in range(n):
        w = 50.0 + 1100.0 * b / (n - 1)
        T = (220.0, -160.0, 260.0, -90.0, 140.0, 0.0, 300.0, -200.0)[b // 20]
        blocks.append(DriveInputs(T_ref=T, w_m=w, u_dc=U_DC, T_magnet=T_MAGNET, T_winding=T_WINDING))
    return blocks


POWERS = ("P_mech", "P_cu", "P_fe", "P_inv")


def reference_1ms(blocks):
    """The two FMUs coupled at 100 us by the reference loop, its record of every 1 ms: the means
    from the plant's exact integrals; the inverter's loss the mean of the plant's per 100 us step."""
    first = blocks[0]
    rows = []
    with ReferenceDrive(fmu_path("IpmsmController"), fmu_path("IpmsmPlant"), T_ref=first.T_ref,
                        w_m=first.w_m, u_dc=first.u_dc, T_magnet=first.T_magnet, T_winding=first.T_winding) as c:
        for inp in blocks:
            for _ in range(10):
                s = c.advance(10 * H, inp.T_ref, inp.w_m, inp.u_dc, inp.T_magnet, inp.T_winding)
                rows.append({name: getattr(s, name) for name in MEANS + INTEGRALS + ENDS})
    return rows


def drive_run(blocks, dt):
    first = blocks[0]
    out = []
    per_block = round(BLOCK / dt)
    with DriveFmu(fmu_path("IpmsmDrive"), T_ref=first.T_ref, w_m=first.w_m, u_dc=first.u_dc,
                  T_magnet=first.T_magnet, T_winding=first.T_winding) as d:
        for inp in blocks:
            for _ in range(per_block):
                out.append(d.advance(dt, inp.T_ref, inp.w_m, inp.u_dc, inp.T_magnet, inp.T_winding))
    return out


@pytest.fixture(scope="module")
def runs():
    blocks = profile()
    return blocks, reference_1ms(blocks), {dt: drive_run(blocks, dt) for dt in (1e-4, 1e-3, 1e-2)}


MEANS = ("T_shaft", "T_e", "i_dc", "P_dc", "P_mech", "P_cu", "P_fe", "P_inv")
INTEGRALS = ("E_dc", "E_mech", "E_cu", "E_fe", "E_inv")
ENDS = ("T_cmd", "T_max", "i_d", "i_q", "region")


def _close(name, got, want, scale, rtol=1e-9):
    got, want = np.asarray(got, float), np.asarray(want, float)
    err = np.max(np.abs(got - want))
    assert err <= rtol * scale, f"{name}: max |drive - two FMUs| = {err:.3g}, allowed {rtol * scale:.3g}"


@pytest.mark.parametrize("dt", [1e-4, 1e-3, 1e-2])
def test_drive_equals_the_two_fmus_coupled_at_100us(runs, dt):
    blocks, ref, drive = runs
    steps = drive[dt]
    group = round(1e-3 / dt) if dt < 1e-3 else 1   # drive steps per 1 ms
    merge = round(dt / 1e-3) if dt > 1e-3 else 1   # 1 ms reference rows per drive step
    assert len(steps) * merge == len(ref) * group
    for name in MEANS:
        d = np.array([getattr(s, name) for s in steps])
        r = np.array([row[name] for row in ref])
        if group > 1:
            d = d.reshape(-1, group).mean(axis=1)
        if merge > 1:
            r = r.reshape(-1, merge).mean(axis=1)
        _close(name, d, r, np.max(np.abs(r)))
    for name in INTEGRALS + ENDS:
        d = np.array([getattr(s, name) for s in steps])[group - 1::group]
        r = np.array([row[name] for row in ref])[merge - 1::merge]
        _close(name, d, r, max(np.max(np.abs(r)), 1.0))


def test_the_run_visits_every_region_and_regenerates(runs):
    _, ref, _ = runs
    assert {row["region"] for row in ref} >= {0, 1, 2, 4}, sorted({row["region"] for row in ref})
    assert min(row["P_dc"] for row in ref) < -10e3 and max(row["P_dc"] for row in ref) > 50e3


def magnetic_energy(i_d: float, i_q: float) -> float:
    """W (J) stored in the machine's field at the currents (i_d, i_q) from zero current, on the
    default map: 1.5 (psi . i - co-energy), the co-energy integrated along the straight path
    (Gauss-Legendre, 24 points; the map is reciprocal, so any path gives it). The magnet's
    temperature shift of psi_d is a constant: it stores nothing."""
    from scenarios.maps.flux_map import DEFAULT_MAP, read_flux_map
    fmap = read_flux_map(DEFAULT_MAP)
    x, w = np.polynomial.legendre.leggauss(24)
    s = 0.5 * (x + 1.0)
    psi_d, psi_q = fmap.flux(s * i_d, s * i_q)
    co_energy = 0.5 * np.sum(w * (psi_d * i_d + psi_q * i_q))
    end_d, end_q = fmap.flux(i_d, i_q)
    return 1.5 * (float(end_d) * i_d + float(end_q) * i_q - co_energy)


def test_energy_balance(runs):
    """E_dc = E_mech + E_cu + E_fe + E_inv + Delta W_magnetic to 1e-6 of the energy throughput,
    from the drive's integrals (the run starts at zero current: Delta W = W at the end currents,
    2.6e-4 of the throughput). The plant integrates its powers exactly over each step (CVODE,
    under error control); sums of the powers after each step (a rectangle rule, the drive before
    this) miss by 3.7e-4 on this run. A term left out of the balance (E_inv is ~1 % of it, E_fe
    ~2 %) fails. The plant's side is checked on its own: E_dc - E_inv is the plant's E_elec
    (test_plant_accuracy checks the integrals against scipy)."""
    _, _, drive = runs
    last = drive[1e-2][-1]
    dW = magnetic_energy(last.i_d, last.i_q)
    residual = last.E_dc - (last.E_mech + last.E_cu + last.E_fe + last.E_inv + dW)
    throughput = sum(abs(s.P_dc) * 1e-2 for s in drive[1e-2])
    print(f"\nenergy residual {residual:.6g} J (Delta W {dW:.6g} J) of {throughput:.6g} J throughput "
          f"({residual / throughput:.3g})")
    assert abs(residual) <= 1e-6 * throughput


def _raw(d: DriveFmu):
    return d.fmu, d.fmu.component


def test_a_step_not_a_multiple_of_sample_time_is_refused_and_the_instance_stays_usable():
    with DriveFmu(fmu_path("IpmsmDrive"), T_ref=100.0, w_m=200.0) as a, \
            DriveFmu(fmu_path("IpmsmDrive"), T_ref=100.0, w_m=200.0) as b:
        a.advance(1e-3, 100.0, 200.0, U_DC, 293.15, 293.15)
        b.advance(1e-3, 100.0, 200.0, U_DC, 293.15, 293.15)
        fmu, c = _raw(a)
        for bad in (1.5e-4, 5e-5, 1e-3 + 1e-8):
            with pytest.raises(FMICallException) as e:
                fmu.fmi2DoStep(c, a.t, bad, 1)
            assert e.value.status == fmi2Error
            assert "not a whole multiple of sample_time" in a.last_messages(1), a.last_messages()
        ra = a.advance(1e-2, 150.0, 220.0, U_DC, 293.15, 293.15)
        rb = b.advance(1e-2, 150.0, 220.0, U_DC, 293.15, 293.15)
        assert ra == rb  # bit for bit: the refused steps changed nothing


def test_leaving_the_flux_map_grid_returns_ok_at_every_step_and_logs_the_warning(tmp_path):
    """The plant's currents leave the map's grid: a linear machine whose grid ends at I_max,
    spun far above its corner speed on a low DC voltage, so that the regulator cannot hold the
    current and it runs towards the short-circuit current psi_m / L_d (800 A). Every step is
    fmi2OK (OMSimulator ends a run on fmi2Warning), the warning is in the log with its status and
    category."""
    I_max, psi_m, L_d = 300.0, 0.08, 1e-4
    path = tmp_path / "small_grid.csv"
    write_flux_map(path, linear_flux_map(L_d, 2e-4, psi_m, I_max))
    w_m, u_dc = 1000.0, 20.0  # back-EMF p psi_m w_m = 320 V against V_max of about 11 V
    params = {"flux_map": str(path), "I_max": I_max, "pole_pairs": 4, "R_s": 0.01}
    with DriveFmu(fmu_path("IpmsmDrive"), params=params, w_m=w_m, logging_on=True) as d:
        fmu, c = _raw(d)
        statuses = []
        for _ in range(50):
            d.set(T_ref=0.0, w_m=w_m, u_dc=u_dc, T_magnet=293.15, T_winding=293.15)
            statuses.append(fmu.fmi2DoStep(c, d.t, 1e-3, 1))
            d.t += 1e-3
        warnings = [(s, cat, m) for s, cat, m in d.messages if "left the flux map" in m]
        assert statuses == [fmi2OK] * 50
        assert warnings and all(s == 1 and cat == "logStatusWarning" for s, cat, _ in warnings), list(d.messages)
        assert warnings[0][2].startswith("plant: ")


def test_every_parameter_of_both_models_once_with_their_defaults():
    from fmpy import read_model_description
    drive = {v.name: v for v in read_model_description(str(fmu_path("IpmsmDrive"))).modelVariables}
    for model in ("IpmsmController", "IpmsmPlant"):
        for v in read_model_description(str(fmu_path(model))).modelVariables:
            if v.causality != "parameter":
                continue
            assert v.name in drive, f"{model}.{v.name} is not a parameter of the drive"
            w = drive[v.name]
            assert (w.causality, w.type, w.unit or "") == ("parameter", v.type, v.unit or ""), v.name
            assert w.start == v.start, (v.name, w.start, v.start)


def test_the_plant_fmu_leaving_the_grid_returns_ok_at_every_step_too():
    """The same for the IpmsmPlant FMU alone (the condition OMSimulator stopped on)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

    path = fmu_path("IpmsmPlant")
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    records = []
    logger = fmi2CallbackLoggerTYPE(lambda env, inst, status, cat, msg: records.append((status, cat.decode(),
                                                                                        msg.decode())))
    cb = fmi2CallbackFunctions()
    cb.logger, cb.allocateMemory, cb.freeMemory = logger, defaultCallbacks.allocateMemory, defaultCallbacks.freeMemory
    p = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier="IpmsmPlant", instanceName="p")
    p.instantiate(callbacks=cb, loggingOn=True)
    p.setupExperiment(startTime=0.0)
    p.enterInitializationMode()
    p.exitInitializationMode()
    p.setReal([vr["w_m"], vr["u_d"], vr["u_q"]], [0.0, -40.0, 0.0])  # drives i_d below the grid's -700 A
    statuses = [p.fmi2DoStep(p.component, k * H, H, 1) for k in range(100)]
    i_d = p.getReal([vr["i_d"]])[0]
    p.terminate()
    p.freeInstance()
    assert i_d < -700.0
    assert statuses == [fmi2OK] * 100
    assert [(s, c) for s, c, m in records if "left the flux map" in m] == [(1, "logStatusWarning")]


def test_fmpy_validate():
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(fmu_path("IpmsmDrive"))) == []


def test_fmu_state_round_trip_continues_bit_for_bit():
    """A serialised state (the sub-models' variables and internal state, the inner step count)
    restored into a fresh instance continues exactly as the original."""
    with DriveFmu(fmu_path("IpmsmDrive"), T_ref=120.0, w_m=400.0) as a, \
            DriveFmu(fmu_path("IpmsmDrive"), T_ref=0.0, w_m=0.0) as b:
        for k in range(5):
            a.advance(1e-2, 120.0 + 10 * k, 400.0 + 20 * k, U_DC, 293.15, 293.15)
        state = a.fmu.serializeFMUstate(a.fmu.getFMUstate())  # (fmpy's FMU2Slave underneath)
        b.fmu.setFMUstate(b.fmu.deSerializeFMUstate(state))
        b.t = a.t
        for k in range(5):
            inputs = (60.0 - 40 * k, 500.0 + 30 * k, U_DC, 293.15, 293.15)
            assert a.advance(1e-3 * (k + 1), *inputs) == b.advance(1e-3 * (k + 1), *inputs)
