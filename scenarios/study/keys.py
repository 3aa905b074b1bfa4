"""What makes a run what it is, as one hash (its key): the run's columns with the content of
what they name (the drive description's files, the cycle's samples after the window), the FMUs'
build (the content hash of the three .fmu) and the Python model's source. A study skips a run
whose key is already "ok" in runs.parquet; any change of these gives new keys, so new runs.

The key does not cover the output-only modules (reports, plots, progress, the command line) nor
the study machinery itself: changing those does not invalidate results.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from scenarios.vehicle.cycles import Cycle

#: bump when the meaning of a key's parts changes
KEY_VERSION = 1

#: the FMUs a run uses (the drive by backend "drive"; the controller for the optimum, and with the
#: plant by the reference loop, backend "reference")
FMU_NAMES = ("IpmsmController.fmu", "IpmsmPlant.fmu", "IpmsmDrive.fmu")

#: scenarios/ modules that do not change a run's numbers (presentation, the command line)
OUTPUT_ONLY = frozenset({"__main__.py", "__init__.py", "check.py", "compare.py", "plots.py", "progress.py", "sweep.py"})
#: scenarios/ subpackages that do not compute a run (the study itself, the map tools)
NOT_IN_A_RUN = frozenset({"study", "maps", "data"})

PACKAGE_DIR = Path(__file__).resolve().parents[1]


def sha256_files(paths) -> str:
    h = hashlib.sha256()
    for p in paths:
        p = Path(p)
        h.update(p.name.encode() + b"\0")
        h.update(hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


def fmu_hash(fmu_dir: Path) -> str:
    """Content hash of the build's three FMUs (16 hex digits)."""
    return sha256_files(Path(fmu_dir) / n for n in FMU_NAMES)[:16]


def code_hash() -> str:
    """Content hash of the scenarios package's modules that compute a run (16 hex digits)."""
    files = sorted(p for p in PACKAGE_DIR.rglob("*.py")
                   if p.name not in OUTPUT_ONLY and p.relative_to(PACKAGE_DIR).parts[0] not in NOT_IN_A_RUN)
    return sha256_files(files)[:16]


def cycle_hash(cycle: Cycle) -> str:
    """The samples the run drives (after the window), not the file's name."""
    h = hashlib.sha256()
    for a in (cycle.time_s, cycle.speed_mps):
        h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
    return h.hexdigest()


def run_key(columns: dict, content: dict, fmu: str, code: str) -> str:
    """The run's key (24 hex digits): `columns` are its spec columns, `content` the hashes of
    what they name (drive, cycle)."""
    doc = dict(version=KEY_VERSION, columns=columns, content=content, fmu=fmu, code=code)
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()[:24]
