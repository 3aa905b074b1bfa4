"""The co-simulation master (scenarios/cosim/master.py; native backend scenarios/native/cosim.cpp) on
the coupling description (fmu_src/coupling/ipmsm_drive.coupling): both backends bit-identical on
torque steps and a speed ramp, and identical to an independent plain loop (scenarios.cosim.fmu, every
input set every step); means are the means of the recorded trace; time is k h; the coupling is
by name (the description's lines in another order give the same numbers; bad descriptions name
their line, names the FMUs lack are refused); bad input raises CosimError naming the FMU (and
leaves the master usable), a failing step stops it; two masters in one process are independent;
the C API is valgrind-clean.
"""
import dataclasses
import math
import shutil
import subprocess

import numpy as np
import pytest
from fmpy import extract

from scenarios.cosim.coupling import DRIVE, Coupling, CouplingError
from scenarios.cosim.fmu import Fmu
from scenarios.cosim.master import SAMPLE_FIELDS, CosimError, DriveCosim, default_library

from conftest import ROOT

H = 1e-4
BACKENDS = ("native", "fmpy")
W0 = 2 * math.pi * 2000 / 60  # 2000 r/min


@pytest.fixture(scope="module")
def library(controller_fmu):
    lib = default_library(controller_fmu)
    if not lib.exists():
        pytest.fail(f"{lib} is missing: build first (./test.sh builds it)")
    return lib


def profile(j):
    """Vehicle-side inputs of chunk j (~50 ms in all): torque steps, a speed ramp, warm parts."""
    T_ref = [0.0, 150.0, 150.0, -100.0, 250.0, 30.0][min(j // 2, 5)]
    w_m = W0 + 40.0 * j  # about +380 r/min per chunk
    return dict(T_ref=T_ref, w_m=w_m, u_dc=355.0 - 2.0 * j, T_magnet=333.15 + j, T_winding=353.15 + 0.5 * j)


CHUNKS = [37, 100, 63, 50, 50, 1, 99, 100, 20, 80, 7, 93]  # 700 steps, odd sizes on purpose


def run(backend, controller_fmu, plant_fmu, library, decimation=1, chunks=CHUNKS, **kw):
    n_out = len(SAMPLE_FIELDS)
    trace = np.full((sum(chunks) // decimation + len(chunks), 1 + n_out), np.nan)
    results, row = [], 0
    with DriveCosim(controller_fmu, plant_fmu, backend=backend, w_m=W0, T_magnet=333.15, T_winding=353.15,
                    library=library, **kw) as cosim:
        for j, n in enumerate(chunks):
            r = cosim.advance(n, **profile(j), trace=trace[row:], decimation=decimation)
            assert r.rows == n // decimation
            row += r.rows
            results.append(r)
        assert cosim.k == sum(chunks)
    return results, trace[:row]


@pytest.fixture(scope="module")
def runs(controller_fmu, plant_fmu, library):
    return {b: run(b, controller_fmu, plant_fmu, library) for b in BACKENDS}


def test_backends_bit_identical(runs):
    (rn, tn), (rf, tf) = runs["native"], runs["fmpy"]
    assert tn.shape == (sum(CHUNKS), 1 + len(SAMPLE_FIELDS))
    assert np.all(np.isfinite(tn))
    assert np.array_equal(tn, tf)  # every output at every step, bit for bit
    for a, b in zip(rn, rf):
        assert a == b  # means, end values, t, k: exactly equal
    # the scenario did something: torque followed the steps, the speed ramp reached field weakening
    T_e, region = tn[:, 1 + SAMPLE_FIELDS.index("T_e")], tn[:, 1 + SAMPLE_FIELDS.index("region")]
    assert T_e.max() > 140 and T_e.min() < -90
    assert {1, 2} <= set(region.astype(int))


# advance()'s means that are exact (the plant's integrals), not the means of the after-step values
EXACT_MEANS = ("P_elec", "P_mech", "P_cu", "P_fe", "T_e", "T_shaft")


def test_means_are_means_of_the_trace(runs):
    results, trace = runs["native"]
    start = 0
    for r, n in zip(results, CHUNKS):
        block = trace[start:start + n, 1:]
        for j, name in enumerate(SAMPLE_FIELDS):
            mean, end = getattr(r.mean, name), getattr(r.end, name)
            assert end == block[-1, j]
            if name in EXACT_MEANS:  # from the plant's integrals (test_drive checks them)
                continue
            # summed in step order, then divided by n: the sequential sum, bit for bit
            assert mean == np.cumsum(block[:, j])[-1] / n, name
            assert mean == pytest.approx(block[:, j].mean(), rel=1e-12, abs=1e-9)
            assert end == block[-1, j]
        start += n
    i_d, i_q = trace[:, 1 + SAMPLE_FIELDS.index("i_d")], trace[:, 1 + SAMPLE_FIELDS.index("i_q")]
    assert np.array_equal(trace[:, 1 + SAMPLE_FIELDS.index("i_abs")], np.sqrt(i_d * i_d + i_q * i_q))
    assert np.array_equal(trace[:, 1 + SAMPLE_FIELDS.index("i_abs_sq")], i_d * i_d + i_q * i_q)
    T_cmd = trace[:, 1 + SAMPLE_FIELDS.index("T_cmd")]
    assert np.all(np.abs(T_cmd) <= 250.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_decimated_trace(runs, backend, controller_fmu, plant_fmu, library):
    chunks = [70, 30, 100, 15]
    _, full = run(backend, controller_fmu, plant_fmu, library, chunks=chunks)
    _, dec = run(backend, controller_fmu, plant_fmu, library, decimation=7, chunks=chunks)
    # row r of a chunk = the state after step (r + 1) * 7 of that chunk
    expect, start = [], 0
    for n in chunks:
        expect += [start + 7 * (r + 1) - 1 for r in range(n // 7)]
        start += n
    assert np.array_equal(dec, full[expect])


def test_same_as_the_plain_fmpy_loop(runs, controller_fmu, plant_fmu):
    """The loop of test_coupled.py (scenarios.cosim.fmu, every input set every step) gives the same
    numbers: the master couples as documented."""
    _, trace = runs["native"]
    i_T_e, i_id = 1 + SAMPLE_FIELDS.index("T_e"), 1 + SAMPLE_FIELDS.index("i_d")
    rows = []
    with Fmu(plant_fmu, w_m=W0, T_magnet=333.15, T_winding=353.15) as p:
        i_d, i_q = p.get("i_d", "i_q")  # the controller starts from the measured current
        c = Fmu(controller_fmu, w_m=W0, T_magnet=333.15, u_dc=355.0, i_d=i_d, i_q=i_q)
        u_d, u_q = c.get("u_d_ref", "u_q_ref")
        k = 0
        for j, n in enumerate(CHUNKS):
            x = profile(j)
            for _ in range(n):
                t = k * H
                i_d, i_q = p.get("i_d", "i_q")
                p.set(u_d=u_d, u_q=u_q, w_m=x["w_m"], T_magnet=x["T_magnet"], T_winding=x["T_winding"])
                c.set(T_ref=x["T_ref"], w_m=x["w_m"], u_dc=x["u_dc"], T_magnet=x["T_magnet"], i_d=i_d, i_q=i_q)
                p.step(t, H)
                c.step(t, H)
                k += 1
                u_d, u_q = c.get("u_d_ref", "u_q_ref")
                rows.append((k * H, p.get("T_e"), p.get("i_d")))
        c.close()
    ref = np.array(rows)
    assert np.array_equal(trace[:, 0], ref[:, 0])
    assert np.array_equal(trace[:, i_T_e], ref[:, 1])
    assert np.array_equal(trace[:, i_id], ref[:, 2])


@pytest.mark.parametrize("backend", BACKENDS)
def test_time_is_k_times_h(backend, controller_fmu, plant_fmu, library):
    h = 1e-4
    trace = np.zeros((10, 1 + len(SAMPLE_FIELDS)))
    with DriveCosim(controller_fmu, plant_fmu, backend=backend, h=h, library=library) as cosim:
        assert cosim.k == 0 and cosim.t == 0.0
        for _ in range(1000):
            r = cosim.advance(1, 0.0, 0.0)
        # 1000 * 1e-4 summed would be 0.09999999999999859; k h is 0.1
        assert r.k == cosim.k == 1000 and r.t == cosim.t == 1000 * h == 0.1
        r = cosim.advance(10, 5.0, 0.0, trace=trace)
        assert r.k == 1010 and r.t == 1010 * h
        assert list(trace[:, 0]) == [(1000 + j) * h for j in range(1, 11)]


def bad_inputs(backend, controller_fmu, plant_fmu, library):
    errors = []
    with DriveCosim(controller_fmu, plant_fmu, backend=backend, w_m=W0, library=library) as cosim:
        good = cosim.advance(20, 50.0, W0)
        cases = [(dict(T_ref=math.nan), "IpmsmController", "T_ref"),
                 (dict(u_dc=0.0), "IpmsmController", "u_dc"),
                 (dict(w_m=math.inf), "IpmsmPlant", "w_m"),  # the plant's inputs are set first
                 (dict(T_winding=-1.0), "IpmsmPlant", "T_winding")]
        for bad, fmu, name in cases:
            x = dict(T_ref=50.0, w_m=W0, u_dc=355.0)
            x.update(bad)
            with pytest.raises(CosimError) as e:
                cosim.advance(20, **x)
            msg = str(e.value)
            assert msg.startswith(fmu + " (") and "fmi2SetReal" in msg and name in msg
            assert "at t = 0.002 s (step k = 20)" in msg and "fmi2Error" in msg
            errors.append(msg)
            assert cosim.k == 20  # nothing happened
        # the refused values were not kept: the next good call continues where it was
        again = cosim.advance(20, 50.0, W0, u_dc=355.0, T_winding=293.15)
        assert again.k == 40 and math.isfinite(again.mean.T_e)
        with pytest.raises(ValueError):
            cosim.advance(0, 50.0, W0)
    assert np.isfinite(good.mean.T_e)
    return errors


def test_bad_input_raises_and_master_stays_usable(controller_fmu, plant_fmu, library):
    texts = [bad_inputs(b, controller_fmu, plant_fmu, library) for b in BACKENDS]
    print("\n".join(texts[0]))
    assert texts[0] == texts[1]  # the same error texts from both backends


@pytest.mark.parametrize("backend", BACKENDS)
def test_failing_step_stops_the_master(backend, controller_fmu, plant_fmu, library):
    # CVODE allowed one internal step: the plant's first step at speed fails (fmi2Error with
    # CVODE's message), the error names the FMU, the function and the time; then the master
    # refuses to go on (the controller and plant are out of step).
    with DriveCosim(controller_fmu, plant_fmu, backend=backend, w_m=1000.0, plant_params={"cvode_max_steps": 1},
                    library=library) as cosim:
        with pytest.raises(CosimError) as e:
            cosim.advance(10, 200.0, 1000.0)
        msg = str(e.value)
        assert msg.startswith("IpmsmPlant (plant, instance 'plant'): fmi2DoStep at t = 0 s (step k = 0) returned "
                              "fmi2Error: ") and "CVODE" in msg
        with pytest.raises(CosimError, match="stopped after a failed step"):
            cosim.advance(10, 200.0, 1000.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_initialisation_error_names_the_fmu(backend, controller_fmu, plant_fmu, library, tmp_path):
    with pytest.raises(CosimError) as e:
        DriveCosim(controller_fmu, plant_fmu, backend=backend, library=library,
                   controller_params={"flux_map": str(tmp_path / "missing.csv")})
    assert str(e.value).startswith("IpmsmController (controller, instance 'controller'): fmi2ExitInitializationMode")
    assert "missing.csv" in str(e.value)
    with pytest.raises(CosimError, match="IpmsmPlant has no variable 'no_such'"):
        DriveCosim(controller_fmu, plant_fmu, backend=backend, library=library, plant_params={"no_such": 1})


def test_two_masters_are_independent(runs, controller_fmu, plant_fmu, library):
    """Two native masters and an fmpy one, interleaved, with different inputs: the first gives
    what it gave alone."""
    alone, _ = runs["native"]
    kw = dict(w_m=W0, T_magnet=333.15, T_winding=353.15, library=library)
    with DriveCosim(controller_fmu, plant_fmu, backend="native", **kw) as a, \
            DriveCosim(controller_fmu, plant_fmu, backend="native", instance_prefix="b_", **kw) as b, \
            DriveCosim(controller_fmu, plant_fmu, backend="fmpy", instance_prefix="c_", **kw) as c:
        for j, n in enumerate(CHUNKS):
            rb = b.advance(n + 3, -80.0, W0 + 100.0)
            ra = a.advance(n, **profile(j))
            rc = c.advance(5, 20.0, W0)
            assert dataclasses.replace(ra, rows=0) == dataclasses.replace(alone[j], rows=0)  # (alone: with a trace)
            assert rb.mean.T_e != ra.mean.T_e and rc.k == 5 * (j + 1)


def test_native_c_api_valgrind_clean(library, controller_fmu, plant_fmu, tmp_path):
    """scenarios/native/cosim_check (three masters, two interleaved; a drive-like profile with
    probes and a trace; a refused input; a failing step; failed instantiations) under valgrind:
    no errors, no leaks (but the FMUs' static libstdc++ pool, see tests/valgrind/static_libstdcxx_pool.supp)."""
    valgrind = shutil.which("valgrind")
    assert valgrind, "valgrind is not installed"
    exe = library.parent.parent / "bin" / "cosim_check"
    assert exe.is_file(), f"{exe} is missing: build the cosim_check target"
    dirs = [extract(str(f), unzipdir=str(tmp_path / f.stem)) for f in (controller_fmu, plant_fmu)]
    supp = ROOT / "tests" / "valgrind" / "static_libstdcxx_pool.supp"
    r = subprocess.run([valgrind, "--error-exitcode=99", "--leak-check=full", "--keep-debuginfo=yes",
                        f"--suppressions={supp}", "--errors-for-leak-kinds=definite,indirect,possible",
                        "--show-leak-kinds=definite,indirect,possible", str(exe), *dirs, "0.02"],
                       capture_output=True, text=True, timeout=600)
    report = r.stdout[-3000:] + "\n" + r.stderr[-5000:]
    assert r.returncode == 0, report
    assert "all checks passed" in r.stdout, report
    assert "ERROR SUMMARY: 0 errors" in r.stderr, report
    assert "definitely lost: 0 bytes" in r.stderr or "All heap blocks were freed" in r.stderr, report


def _permuted(text: str) -> str:
    """The description with its connection and external-input lines in reverse order."""
    lines = text.splitlines()
    links = [i for i, line in enumerate(lines) if "->" in line and not line.lstrip().startswith("#")]
    permuted = list(lines)
    for i, j in zip(links, reversed(links)):
        permuted[i] = lines[j]
    return "\n".join(permuted)


@pytest.mark.parametrize("backend", BACKENDS)
def test_coupling_is_by_name_not_by_position(runs, backend, controller_fmu, plant_fmu, library):
    """The description's lines in another order (so other value-reference orders in every
    fmi2SetReal): the same numbers, bit for bit."""
    permuted = Coupling.parse(_permuted(DRIVE.text))
    assert permuted.connections == DRIVE.connections[::-1] and permuted.inputs == DRIVE.inputs[::-1]
    results, trace = run(backend, controller_fmu, plant_fmu, library, coupling=permuted)
    assert np.array_equal(trace, runs["native"][1])
    assert results == runs["native"][0]


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


def test_a_description_the_fmus_do_not_fit_is_refused(controller_fmu, plant_fmu, library):
    wrong = Coupling.parse(DRIVE.text.replace("-> plant.u_q", "-> plant.u_x"))
    for backend in BACKENDS:
        with pytest.raises(CosimError, match="IpmsmPlant has no variable 'u_x'"):
            DriveCosim(controller_fmu, plant_fmu, backend=backend, library=library, coupling=wrong)


@pytest.mark.parametrize("text", [
    "unit plant IpmsmPlant\nstep 1e-4\nplant.i_d => controller.i_d\n",
    "unit plant IpmsmPlant\nstep 1e-4\nplant.i_d -> controller.i_d\n",
    "unit p P\nunit c C\nstep 1e-4\nw -> p.w\nw2 -> p.w\n",
    "unit p P\nunit p P\n",
    "unit p P\n",
])
def test_cpp_and_python_read_descriptions_alike(library, text):
    """coupling.hpp (in the native master) and scenarios/cosim/coupling.py refuse a bad description
    with the same words."""
    from scenarios.cosim.master import _NativeBackend
    lib = _NativeBackend._load(library)
    with pytest.raises(CouplingError) as e:
        Coupling.parse(text)
    m = lib.ipmsm_cosim_new(text.encode(), 1e-4, _NativeBackend._LOG_FN(0), None)
    try:
        assert lib.ipmsm_cosim_instantiate(m, b"p", b"/nonexistent", b"x", 0) == -1
        assert lib.ipmsm_cosim_error(m).decode() == str(e.value)
    finally:
        lib.ipmsm_cosim_free(m)
