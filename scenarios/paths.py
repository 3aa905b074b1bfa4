"""Where the project's files are: the repository (the package is installed editable, `pip install
-e .`), its default build folder, and the data shared by every clone beside it."""
from __future__ import annotations

import os
from pathlib import Path

#: the repository
ROOT = Path(__file__).resolve().parents[1]

#: the CMake build folder the scenarios take the FMUs (fmu/) and the native master (lib/) from
BUILD_DIR = ROOT / "build"

#: the read-only data shared by the clones (drive cycles, OCV fits, measured flux maps):
#: `<repo>/../shared`, or $IPMSM_SHARED_DIR (a clone or worktree elsewhere)
SHARED_DIR = Path(os.environ.get("IPMSM_SHARED_DIR") or ROOT.parent / "shared")
