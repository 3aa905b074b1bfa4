"""The IpmsmPlant FMU's binary under valgrind (memcheck, --leak-check=full): the C++ harness
tests/cpp/plant_fmu_harness.cpp (built as <build>/bin/plant_fmu_harness by plant/CMakeLists.txt)
dlopens the packaged FMU and runs instantiate -> run -> reset -> run -> terminate -> free,
free without terminate, FMU states (get, set, serialise, deserialise into a fresh instance, free
the instance with states alive), errors (missing map, NaN input, CVODE failure) and two
instances interleaved. No Python in the process, so every report is the FMU's.

Fails (not skips) if valgrind or the harness is missing.
"""
import shutil
import subprocess
from pathlib import Path

from fmpy import extract

from conftest import BUILD_FMU


def test_plant_fmu_is_clean_under_valgrind(plant_fmu, tmp_path):
    valgrind = shutil.which("valgrind")
    assert valgrind, "valgrind is not installed"
    harness = BUILD_FMU.parent / "bin" / "plant_fmu_harness"
    assert harness.is_file(), f"{harness} is missing: build the plant_fmu_harness target"
    unzipped = Path(extract(str(plant_fmu), unzipdir=str(tmp_path / "IpmsmPlant")))
    # memcheck is ~50x slower: 60 steps per phase are plenty to exercise every path.
    r = subprocess.run([valgrind, "--error-exitcode=99", "--leak-check=full",
                        "--errors-for-leak-kinds=definite,indirect,possible",
                        "--show-leak-kinds=definite,indirect,possible",
                        str(harness), str(unzipped), "60"],
                       capture_output=True, text=True, timeout=600)
    report = r.stdout[-4000:] + "\n" + r.stderr[-6000:]
    assert r.returncode == 0, report
    assert "OK (0 failed checks)" in r.stdout, report
    assert "ERROR SUMMARY: 0 errors" in r.stderr, report
    assert "definitely lost: 0 bytes" in r.stderr or "All heap blocks were freed" in r.stderr, report
