import os
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
SHARED = ROOT.parent / "shared"
BUILD_FMU = Path(os.environ.get("IPMSM_FMU_DIR", ROOT / "build" / "fmu"))
# The FMUs under test carry binaries/win64 (issue 17): unless the set-up was told IPMSM_WIN64=OFF,
# or they come from the sanitizer build (build-asan/, Linux only).
WIN64_BUILT = (os.environ.get("IPMSM_WIN64", "ON").upper() != "OFF"
               and not os.environ.get("IPMSM_UNDER_SANITIZER"))


def same(a, b) -> bool:
    """Bit-identical rows of outputs."""
    return np.array(a, dtype=float).tobytes() == np.array(b, dtype=float).tobytes()


def fmu_path(name: str) -> Path:
    p = BUILD_FMU / f"{name}.fmu"
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
    return ROOT / "fmu_src" / "resources" / "ev_ipmsm_default.csv"


@pytest.fixture(scope="session")
def measured_map_path() -> Path:
    return SHARED / "data" / "fluxmaps" / "baldor_5p6kW_pmsyrm_measured.csv"


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: long runs (full drive cycles, big sweeps); run with -m slow")
