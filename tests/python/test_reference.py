"""The reference loop (scenarios/cosim/reference.py: IpmsmController + IpmsmPlant coupled in Python
by the coupling description, fmu_src/coupling/ipmsm_drive.coupling, a plain loop by variable name):
the same step record as the IpmsmDrive FMU (the fast path) on torque steps and a speed ramp, and
the same currents at every inner step; the drive's record filled by name; time is k h; the coupling is by name
(the description's lines in another order give the same numbers, bad descriptions name their line,
names the FMUs lack are refused); bad input raises CosimError naming the FMU and leaves the loop
usable; a failing step raises naming the FMU and the call.
"""
import dataclasses
import math

import pytest

from scenarios.cosim.coupling import DRIVE, Coupling, CouplingError
from scenarios.cosim.drive_fmu import DriveFmu
from scenarios.cosim.fmu import CosimError
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


def test_every_inner_step_as_the_drive_fmus(controller_fmu, plant_fmu):
    """The plain loop (every coupled input set every step by name, as simulate_fmi2_cs.c) and
    IpmsmDrive (the same coupling inside, in C++) stepped by one inner step at a time: the same
    currents and commands at every step, bit for bit."""
    chunks = CHUNKS[:4]
    k = 0
    with reference(controller_fmu, plant_fmu) as ref, DriveFmu(fmu_path("IpmsmDrive"), **START) as drive:
        for j, n in enumerate(chunks):
            for _ in range(n):
                a, b = ref.advance(H, **profile(j)), drive.advance(H, **profile(j))
                assert (a.i_d, a.i_q, a.i_d_ref, a.i_q_ref, a.T_cmd) == (b.i_d, b.i_q, b.i_d_ref, b.i_q_ref, b.T_cmd), k
                k += 1
    assert k == sum(chunks)


def test_the_record_is_filled_by_name():
    """Every field of the drive's record is the FMU's output of that name (read here one by one
    through the FMU handle), so a new output is one field of DriveStep."""
    with DriveFmu(fmu_path("IpmsmDrive"), **START) as drive:
        step = drive.advance(37 * H, **profile(0))
        names = [f.name for f in dataclasses.fields(step)]
        assert set(names) <= set(drive.vars)
        assert [getattr(step, n) for n in names] == drive.get(*names)


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


def test_the_drive_fmu_checks_every_calls_status():
    """An input the drive refuses (fmi2SetReal returns fmi2Error) ends the step with the call and
    the FMU's words; before, the step ran on the previous inputs."""
    with DriveFmu(fmu_path("IpmsmDrive"), **START) as drive:
        good = drive.advance(10 * H, **profile(1))
        bad = {**profile(1), "T_winding": -1.0}
        with pytest.raises(CosimError, match=r"^IpmsmDrive: fmi2SetReal of the inputs failed .*T_winding"):
            drive.advance(10 * H, **bad)
        assert drive.t == pytest.approx(10 * H) and math.isfinite(good.T_e)
