"""The reference loop (scenarios/cosim/reference.py: IpmsmController + IpmsmPlant coupled in Python
by the coupling description, fmu_src/coupling/ipmsm_drive.coupling): the same step record as the
IpmsmDrive FMU (the fast path) on torque steps and a speed ramp, and the same currents as an
independent plain loop (every input set every step by name); time is k h; the coupling is by name
(the description's lines in another order give the same numbers, bad descriptions name their line,
names the FMUs lack are refused); bad input raises CosimError naming the FMU and leaves the loop
usable; a failing step raises naming the FMU and the call.
"""
import dataclasses
import math

import pytest

from scenarios.cosim.coupling import DRIVE, Coupling, CouplingError
from scenarios.cosim.drive_fmu import DriveFmu
from scenarios.cosim.fmu import CosimError, Fmu
from scenarios.cosim.reference import ReferenceDrive

from conftest import fmu_path

H = 1e-4
W0 = 2 * math.pi * 2000 / 60  # 2000 r/min
START = dict(w_m=W0, T_magnet=333.15, T_winding=353.15)


def profile(j):
    """Vehicle-side inputs of chunk j (~50 ms in all): torque steps, a speed ramp, warm parts."""
    T_ref = [0.0, 150.0, 150.0, -100.0, 250.0, 30.0][min(j // 2, 5)]
    w_m = W0 + 40.0 * j  # about +380 r/min per chunk
    return dict(T_ref=T_ref, w_m=w_m, u_dc=355.0 - 2.0 * j, T_magnet=333.15 + j, T_winding=353.15 + 0.5 * j)


CHUNKS = [37, 100, 63, 50, 50, 1, 99, 100, 20, 80, 7, 93]  # 700 steps, odd sizes on purpose


def run(drive, chunks=CHUNKS):
    with drive:
        return [drive.advance(n * H, **profile(j)) for j, n in enumerate(chunks)]


def reference(controller_fmu, plant_fmu, **kw):
    return ReferenceDrive(controller_fmu, plant_fmu, **START, **kw)


@pytest.fixture(scope="module")
def records(controller_fmu, plant_fmu):
    return run(reference(controller_fmu, plant_fmu))


@pytest.fixture(scope="module")
def drive_records():
    return run(DriveFmu(fmu_path("IpmsmDrive"), **START))


def test_the_same_record_as_the_drive_fmu(records, drive_records):
    """IpmsmDrive couples the same models by the same description inside: every output of every
    step agrees to rounding, the inverter's loss included (the plant's in both)."""
    for j, (r, d) in enumerate(zip(records, drive_records)):
        for name, value in dataclasses.asdict(r).items():
            assert value == pytest.approx(getattr(d, name), rel=1e-9, abs=1e-9, nan_ok=True), (j, name)


def test_the_inverter_loss_is_the_drive_fmus(records, drive_records):
    """One inverter model: the reference loop reads the plant FMU's P_inv after each inner step and
    IpmsmDrive reads its plant's; the step means and the energy agree to 1e-9 relative (the same
    C++ code on the same currents: in fact bit for bit), and the loss is there (not 0)."""
    assert len(records) == len(drive_records) == len(CHUNKS)
    for j, (r, d) in enumerate(zip(records, drive_records)):
        assert (r.P_inv > 0.0) == (j > 0), j  # the first chunk: T_ref = 0 from rest, no current, no loss
        for name in ("P_inv", "E_inv", "P_dc", "i_dc", "E_dc"):
            assert getattr(r, name) == pytest.approx(getattr(d, name), rel=1e-9, abs=0.0), (j, name)
    assert records[-1].E_inv == pytest.approx(sum(r.P_inv * n * H for r, n in zip(records, CHUNKS)), rel=1e-9)


def test_same_as_the_plain_fmpy_loop(controller_fmu, plant_fmu):
    """A loop by hand (scenarios.cosim.fmu, every input set every step) gives the same currents,
    bit for bit: the reference loop couples as the description says."""
    chunks = CHUNKS[:4]
    ref, steps = reference(controller_fmu, plant_fmu), []
    with ref:
        for j, n in enumerate(chunks):
            steps += [ref.advance(H, **profile(j)) for _ in range(n)]
    with Fmu(plant_fmu, **START) as p:
        i_d, i_q = p.get("i_d", "i_q")  # the controller starts from the measured current
        with Fmu(controller_fmu, w_m=W0, T_magnet=333.15, T_winding=353.15, u_dc=355.0, i_d=i_d, i_q=i_q) as c:
            u_d, u_q = c.get("u_d_ref", "u_q_ref")
            k = 0
            for j, n in enumerate(chunks):
                x = profile(j)
                for _ in range(n):
                    i_d, i_q = p.get("i_d", "i_q")
                    p.set(u_d=u_d, u_q=u_q, w_m=x["w_m"], T_magnet=x["T_magnet"], T_winding=x["T_winding"])
                    c.set(T_ref=x["T_ref"], w_m=x["w_m"], u_dc=x["u_dc"], T_magnet=x["T_magnet"],
                          T_winding=x["T_winding"], i_d=i_d, i_q=i_q)
                    p.step(k * H, H)
                    c.step(k * H, H)
                    u_d, u_q = c.get("u_d_ref", "u_q_ref")
                    assert (steps[k].i_d, steps[k].i_q) == tuple(p.get("i_d", "i_q")), k
                    k += 1


def test_time_is_k_times_h(controller_fmu, plant_fmu):
    with reference(controller_fmu, plant_fmu) as ref:
        for _ in range(1000):
            ref.advance(H, 0.0, W0, 355.0, 333.15, 353.15)
        # the last fmi2DoStep started at t_999 = 999 h (not a sum of 999 h, which drifts)
        assert ref.k == 1000 and ref.units["plant"].t == 999 * H == 0.0999


def test_bad_input_raises_and_the_loop_stays_usable(controller_fmu, plant_fmu):
    with reference(controller_fmu, plant_fmu) as ref:
        good = ref.advance(20 * H, 50.0, W0, 355.0, 333.15, 353.15)
        for bad, fmu, name in [(dict(T_ref=math.nan), "IpmsmController", "T_ref"),
                               (dict(u_dc=0.0), "IpmsmPlant", "u_dc"),  # the inverter's (the plant's loss)
                               (dict(w_m=math.inf), "IpmsmPlant", "w_m"),  # the plant's inputs are set first
                               (dict(T_winding=-1.0), "IpmsmPlant", "T_winding")]:
            x = {**dict(T_ref=50.0, w_m=W0, u_dc=355.0, T_magnet=333.15, T_winding=353.15), **bad}
            with pytest.raises(CosimError) as e:
                ref.advance(20 * H, **x)
            assert str(e.value).startswith(fmu + ":") and name in str(e.value), str(e.value)
            assert ref.k == 20  # nothing happened
        again = ref.advance(20 * H, 50.0, W0, 355.0, 333.15, 353.15)
        assert ref.k == 40 and math.isfinite(again.T_e) and math.isfinite(good.T_e)
        with pytest.raises(ValueError):
            ref.advance(0.0, 50.0, W0, 355.0, 333.15, 353.15)


def test_failing_step_names_the_fmu(controller_fmu, plant_fmu):
    # CVODE allowed one internal step: the plant's first step at speed fails (fmi2Error with
    # CVODE's message); the error names the FMU, the call and the time.
    with ReferenceDrive(controller_fmu, plant_fmu, plant_params={"cvode_max_steps": 1}, w_m=1000.0) as ref:
        with pytest.raises(CosimError) as e:
            ref.advance(10 * H, 200.0, 1000.0, 355.0, 293.15, 293.15)
    msg = str(e.value)
    assert msg.startswith("IpmsmPlant: fmi2DoStep failed at t = 0 s (status 3)") and "CVODE" in msg, msg


def test_initialisation_error_names_the_fmu(controller_fmu, plant_fmu, tmp_path):
    with pytest.raises(CosimError) as e:
        ReferenceDrive(controller_fmu, plant_fmu, controller_params={"flux_map": str(tmp_path / "missing.csv")})
    assert str(e.value).startswith("IpmsmController: fmi2ExitInitializationMode") and "missing.csv" in str(e.value)
    with pytest.raises(CosimError, match="IpmsmPlant has no variable 'no_such'"):
        ReferenceDrive(controller_fmu, plant_fmu, plant_params={"no_such": 1})


def _permuted(text: str) -> str:
    """The description with its connection and external-input lines in reverse order."""
    lines = text.splitlines()
    links = [i for i, line in enumerate(lines) if "->" in line and not line.lstrip().startswith("#")]
    permuted = list(lines)
    for i, j in zip(links, reversed(links)):
        permuted[i] = lines[j]
    return "\n".join(permuted)


def test_coupling_is_by_name_not_by_position(records, controller_fmu, plant_fmu):
    """The description's lines in another order (so other value-reference orders in every
    fmi2SetReal): the same numbers, bit for bit."""
    permuted = Coupling.parse(_permuted(DRIVE.text))
    assert permuted.connections == DRIVE.connections[::-1] and permuted.inputs == DRIVE.inputs[::-1]
    assert run(reference(controller_fmu, plant_fmu, coupling=permuted)) == records


@pytest.mark.parametrize("text, line, why", [
    ("unit plant IpmsmPlant\nstep 1e-4\nplant.i_d => controller.i_d\n", 3, "expected: unit, step"),
    ("unit plant IpmsmPlant\nstep 1e-4\nplant.i_d -> controller.i_d\n", 3, "no unit 'controller'"),
    ("unit plant IpmsmPlant\nunit plant IpmsmPlant\n", 2, "declared twice"),
    ("unit plant IpmsmPlant\nstep -1\n", 2, "the step must be a number > 0"),
    ("unit p P\nunit c C\nstep 1e-4\nw -> p.w\nw2 -> p.w\n", 5, "p.w is fed twice"),
    ("unit p P\nunit c C\nstep 1e-4\np.y -> c.u, c.v\n", 4, "a connection feeds one input"),
])
def test_coupling_description_errors_name_the_line(text, line, why):
    with pytest.raises(CouplingError, match=f"line {line} .*{why}"):
        Coupling.parse(text)


def test_a_description_the_fmus_do_not_fit_is_refused(controller_fmu, plant_fmu):
    wrong = Coupling.parse(DRIVE.text.replace("-> plant.u_q", "-> plant.u_x"))
    with pytest.raises(CosimError, match="IpmsmPlant has no variable 'u_x'"):
        reference(controller_fmu, plant_fmu, coupling=wrong)
