"""Where the project's files are: the package's own data (drive cycles, OCV fits, flux maps, all
copied into the repository with their sources: data/*/SOURCES.md), the repository and its default
build folder. Nothing here points outside the repository: a clone runs alone."""
from __future__ import annotations

from pathlib import Path

#: the installed package
PACKAGE_DIR = Path(__file__).resolve().parents[1]

#: the repository (the package is installed editable, `pip install -e .`)
ROOT = PACKAGE_DIR.parent

#: the CMake build folder the scenarios take the FMUs (fmu/) from
BUILD_DIR = ROOT / "build"

#: the data the scenarios run on, shipped inside the package: cycles/, fluxmaps/ (fluxmaps/real/:
#: real published maps as published), ocv_nmc_cell_and_96s.csv; each folder's SOURCES.md says
#: where every file came from
DATA_DIR = PACKAGE_DIR / "data"
