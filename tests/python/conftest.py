"""Fixtures of the system tests. The code under test comes from the installed package
(`pip install -e .`, scripts/setup.sh); the helpers beside the tests (fmi2_raw, brute_force,
drive_step) import as top-level modules because pytest puts this folder on sys.path.

The tests' one FMU wrapper is fmi2_raw.Instance (every FMI 2.0 function, the raw status, a
log); `unzipped` and `fmu_instances` below hand out FMUs and instances of it."""
import os

# One OpenBLAS thread for the tests and every child they start (the environment is inherited),
# set before numpy loads OpenBLAS. The suite keeps the cores busy itself (FMU and CLI children,
# Dask workers, to which distributed's nanny gives one BLAS thread the same way), and an extra
# OpenBLAS thread waits for work by spinning: on vector products of a few 10^4 points (the
# iron-loss fit of a SyR-e map) the spinning costs tens of times the work. Results do not depend
# on it (the fit's coefficients are the same bit for bit); a caller's own setting is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from pathlib import Path  # noqa: E402 (after the BLAS setting above)

import fmi3_raw as raw3  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from scenarios.core import paths  # noqa: E402
from scenarios.maps.flux_map import DEFAULT_MAP  # noqa: E402

import fmi2_raw as raw  # noqa: E402

ROOT = paths.ROOT
DATA = paths.DATA_DIR
BUILD_FMU = Path(os.environ.get("IPMSM_FMU_DIR", paths.BUILD_DIR / "fmu"))
# The FMUs under test carry binaries/win64 (issue 17): unless the set-up was told IPMSM_WIN64=OFF,
# or they come from the sanitizer build (build-asan/, Linux only).
WIN64_BUILT = (os.environ.get("IPMSM_WIN64", "ON").upper() != "OFF"
               and not os.environ.get("IPMSM_UNDER_SANITIZER"))


#: How much longer a run takes on the AddressSanitizer build (tests/python/test_sanitizers.py runs
#: this suite there): measured on this 2-core machine under load, the UDDS run of
#: test_self_contained took 22 s on the normal build and 172 s on the ASan one. A bound that
#: catches a hang, or says "refused at once", is scaled by it so that a slow but correct run passes.
UNDER_SANITIZER = os.environ.get("IPMSM_UNDER_SANITIZER") == "1"
SANITIZER_SLOWDOWN = 10 if UNDER_SANITIZER else 1


def patient(seconds: float) -> float:
    """A time bound for the build under test: `seconds` on the normal build."""
    return seconds * SANITIZER_SLOWDOWN


def address_space_limit(nbytes: int):
    """A child's preexec_fn that caps its address space at `nbytes` (RLIMIT_AS): a command that
    maps more fails instead of exhausting the machine. On the sanitizer build the cap is left off:
    ASan reserves terabytes of address space for its shadow memory at start-up, so the child keeps
    its time bound only (hostile_child.py likewise)."""
    def limit() -> None:
        if not UNDER_SANITIZER:
            import resource
            resource.setrlimit(resource.RLIMIT_AS, (nbytes, nbytes))
    return limit


def same(a, b) -> bool:
    """Bit-identical rows of outputs."""
    return np.array(a, dtype=float).tobytes() == np.array(b, dtype=float).tobytes()


def fmu_path(name: str) -> Path:
    p = BUILD_FMU / f"{name}.fmu"
    if not p.exists():
        pytest.fail(f"{p} is missing: build first (./test.sh builds it)")
    return p


#: the FMI 3.0 FMUs (issue 36): fmu3/ beside the FMI 2.0 ones, or $IPMSM_FMU3_DIR
BUILD_FMU3 = Path(os.environ.get("IPMSM_FMU3_DIR", BUILD_FMU.parent / "fmu3"))


def fmu3_path(name: str) -> Path:
    p = BUILD_FMU3 / f"{name}.fmu"
    if not p.exists():
        pytest.fail(f"{p} is missing: build first (./test.sh builds it)")
    return p


@pytest.fixture(scope="session")
def controller_fmu() -> Path:
    return fmu_path("IpmsmController")


@pytest.fixture(scope="session")
def plant_fmu() -> Path:
    return fmu_path("IpmsmPlant")


@pytest.fixture(scope="session")
def default_map_path() -> Path:
    return DEFAULT_MAP


@pytest.fixture(scope="session")
def measured_map_path() -> Path:
    return DATA / "fluxmaps" / "baldor_5p6kW_pmsyrm_measured.csv"


@pytest.fixture(scope="session")
def unzipped(tmp_path_factory):
    """unzipped(name) -> fmi2_raw.Unzipped of $IPMSM_FMU_DIR/<name>.fmu, extracted once a session."""
    cache = {}

    def get(name: str) -> raw.Unzipped:
        if name not in cache:
            cache[name] = raw.Unzipped(fmu_path(name), tmp_path_factory.mktemp(name))
        return cache[name]

    return get


@pytest.fixture(scope="session")
def unzipped3(tmp_path_factory):
    """unzipped3(name) -> fmi3_raw.Unzipped3 of the FMI 3.0 <name>.fmu, extracted once a session."""
    cache = {}

    def get(name: str) -> raw3.Unzipped3:
        if name not in cache:
            cache[name] = raw3.Unzipped3(fmu3_path(name), tmp_path_factory.mktemp(f"{name}3"))
        return cache[name]

    return get


def _instances(unzip, instance_class):
    """A fixture's body for either standard: new(name, instance_name="instance", **options) ->
    instance_class(unzip(name), ...), every one freed after the test."""
    made = []

    def new(name: str, instance_name: str = "instance", **options):
        inst = instance_class(unzip(name), instance_name, **options)
        made.append(inst)
        return inst

    yield new
    for inst in made:
        inst.free()


@pytest.fixture
def instances3(unzipped3):
    """instances3(name, instance_name="instance", **Instance3 options) -> an fmi3_raw.Instance3 of
    that FMI 3.0 FMU, freed after the test."""
    yield from _instances(unzipped3, raw3.Instance3)


@pytest.fixture
def fmu_instances(unzipped):
    """fmu_instances(name, instance_name="instance", **Instance options) -> an fmi2_raw.Instance
    of that FMU, freed after the test."""
    yield from _instances(unzipped, raw.Instance)


@pytest.fixture
def make(fmu_instances):
    """make(name, instance_name=..., **Instance options): a fresh instance, freed after the test."""
    count = iter(range(1 << 30))

    def new(name, **kw):
        return fmu_instances(name, kw.pop("instance_name", f"{name}{next(count)}"), **kw)

    return new


@pytest.fixture
def unwritable_folder(tmp_path):
    """A folder no one may write into, root included: mode 555, and where that does not stop the
    user (root ignores modes) the immutable attribute (chattr +i, ext4 and most Linux file
    systems), which stops root too. Skips only where neither is possible."""
    import shutil
    import subprocess

    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    immutable = False
    if os.access(folder, os.W_OK) and shutil.which("chattr"):
        immutable = subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode == 0
    if os.access(folder, os.W_OK):
        pytest.skip("this user may write into a folder of mode 555 and chattr +i is not available")
    try:
        yield folder
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
        folder.chmod(0o755)
