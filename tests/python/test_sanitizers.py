"""The tests again, on binaries built with AddressSanitizer and UBSan (issue 5): build-asan/, made
by scripts/sanitize.sh (./test.sh runs it in its build stage).

- Default run: the pytest modules that load the FMUs (the hostile-input tests, with the fuzz
  harness built with ASan and leak checking on, the glue's tests, conformance, the three masters,
  both FMUs' system tests and the coupled drive; the FMI 3.0 FMUs' tests and hostile corpus) in a
  Python with ASan preloaded, on the ASan FMUs. Any ASan or UBSan report aborts that process
  (halt_on_error; UBSan is built with -fno-sanitize-recover) and fails this test with the report.
- Slow (./test.sh -m slow): the whole suite, after building everything with ASan: the C++ unit
  tests (ctest, leak checking on) and every pytest module; and the C++ unit tests of the normal
  build under valgrind.
Valgrind runs on the normal build: the fuzz harness on both FMUs (tests/python/test_hostile.py,
default and a longer slow run) and the plant harness (test_plant_valgrind.py).

Without build-asan/ these tests are skipped, unless IPMSM_REQUIRE_SANITIZERS=1 (./test.sh sets
it): then they fail.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import BUILD_FMU, ROOT

ASAN_BUILD = Path(os.environ.get("IPMSM_ASAN_BUILD", ROOT / "build-asan"))
REQUIRED = os.environ.get("IPMSM_REQUIRE_SANITIZERS") == "1"
PYTHON_TESTS = ROOT / "tests" / "python"
# the modules that load the FMUs, in the default pass
DEFAULT_MODULES = ["test_hostile.py", "test_hostile_bounds.py", "test_fmi_glue.py", "test_conformance.py",
                   "test_importers.py", "test_controller_fmu.py", "test_plant_fmu.py", "test_coupled.py",
                   "test_fmi3.py", "test_hostile_fmi3.py", "test_fmi3_arrays.py"]

pytestmark = pytest.mark.skipif(os.environ.get("IPMSM_UNDER_SANITIZER") == "1",
                                reason="already running under the sanitizers")


def _need(*paths: Path):
    missing = [p for p in paths if not p.exists()]
    if missing:
        message = f"{', '.join(map(str, missing))} missing: run scripts/sanitize.sh (./test.sh does)"
        if REQUIRED:
            pytest.fail(message)
        pytest.skip(message)


def _runtime(name: str) -> str:
    path = subprocess.run(["gcc", f"-print-file-name={name}"], capture_output=True, text=True,
                          check=True).stdout.strip()
    assert os.path.isabs(path), f"gcc does not know {name}"
    return path


def _env(log_dir: Path, leaks: bool) -> dict:
    log = f"log_path={log_dir / 'sanitizer'}"
    return {**os.environ,
            "IPMSM_FMU_DIR": str(ASAN_BUILD / "fmu"),
            "IPMSM_UNDER_SANITIZER": "1",
            # ASan first, and libstdc++ so that it can intercept C++ exceptions in the FMUs
            "LD_PRELOAD": f"{_runtime('libasan.so')} {_runtime('libstdc++.so')}",
            "ASAN_OPTIONS": f"detect_leaks={int(leaks)}:halt_on_error=1:strict_string_checks=1:"
                            f"detect_stack_use_after_return=1:check_initialization_order=1:{log}",
            "UBSAN_OPTIONS": f"halt_on_error=1:print_stacktrace=1:{log}"}


def _reports(log_dir: Path) -> str:
    return "\n".join(p.read_text(errors="replace")[-8000:] for p in sorted(log_dir.glob("sanitizer*")))


def _pytest(args, log_dir: Path, timeout: int, deselect: str = "not valgrind"):
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-k", deselect, *args]
    r = subprocess.run(cmd, cwd=ROOT, env=_env(log_dir, leaks=False), capture_output=True, text=True,
                       timeout=timeout)
    tail = "\n".join(r.stdout.strip().splitlines()[-25:])
    print(f"\n[pytest under ASan/UBSan] {tail.splitlines()[-1] if tail else ''}")
    return r, f"{tail}\n{r.stderr[-3000:]}\n{_reports(log_dir)}"


def test_fmu_tests_under_asan_and_ubsan(tmp_path):
    _need(ASAN_BUILD / "fmu" / "IpmsmController.fmu", ASAN_BUILD / "fmu" / "IpmsmPlant.fmu",
          ASAN_BUILD / "fmu" / "ToyLag.fmu", ASAN_BUILD / "bin" / "fmu_fuzz",
          *(ASAN_BUILD / "fmu3" / f"{name}.fmu" for name in ("IpmsmController", "IpmsmPlant", "IpmsmDrive")))
    modules = [str(PYTHON_TESTS / m) for m in DEFAULT_MODULES]
    r, report = _pytest([*modules, "-m", "not slow"], tmp_path, timeout=1500,
                        deselect="not valgrind and not vdmcheck")
    assert r.returncode == 0, report
    assert not _reports(tmp_path), report


@pytest.mark.slow
def test_state_fuzz_under_asan_and_ubsan(tmp_path):
    """Every variant of every FMU's serialised state (test_state_fuzz.py, thousands each, slow ones
    included) on the ASan FMUs: a refused or accepted state never reads or writes out of bounds."""
    _need(ASAN_BUILD / "fmu" / "IpmsmController.fmu", ASAN_BUILD / "fmu" / "IpmsmPlant.fmu",
          ASAN_BUILD / "fmu" / "IpmsmDrive.fmu")
    r, report = _pytest([str(PYTHON_TESTS / "test_state_fuzz.py")], tmp_path, timeout=3600)
    assert r.returncode == 0, report
    assert not _reports(tmp_path), report


@pytest.mark.slow
def test_whole_suite_under_asan_and_ubsan(tmp_path):
    subprocess.run(["bash", str(ROOT / "scripts" / "sanitize.sh"), "--full"], check=True, timeout=3600)
    ctest = subprocess.run(["ctest", "--test-dir", str(ASAN_BUILD), "--output-on-failure", "-j", str(os.cpu_count())],
                           env={**_env(tmp_path, leaks=True), "LD_PRELOAD": ""}, capture_output=True, text=True,
                           timeout=3600)
    print("\n[ctest under ASan/UBSan] " + "".join(l for l in ctest.stdout.splitlines(True) if "tests passed" in l))
    assert ctest.returncode == 0, ctest.stdout[-6000:] + _reports(tmp_path)
    r, report = _pytest([str(PYTHON_TESTS), "-m", "not slow"], tmp_path, timeout=7200)
    assert r.returncode == 0, report
    assert not _reports(tmp_path), report


@pytest.mark.slow
@pytest.mark.parametrize("binary,gtest_filter", [
    ("fmi_glue_unit_tests", "*"),
    # valgrind emulates x86 floating point in 64 bits: the adversarial quartic tests (extreme
    # exponents) give other roundings there, not memory errors
    ("unit_tests", "-QuarticAdversarial.*"),
])
def test_cpp_unit_tests_under_valgrind(binary, gtest_filter):
    import shutil
    valgrind = shutil.which("valgrind")
    assert valgrind, "valgrind is not installed"
    exe = BUILD_FMU.parent / "bin" / binary
    assert exe.is_file(), f"{exe} is missing"
    r = subprocess.run([valgrind, "-q", "--error-exitcode=99", "--leak-check=full",
                        "--errors-for-leak-kinds=definite,indirect,possible", str(exe),
                        f"--gtest_filter={gtest_filter}"], capture_output=True, text=True, timeout=3600)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-8000:]
