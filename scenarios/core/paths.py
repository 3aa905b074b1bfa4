"""Where the project's files are: the package's own data (drive cycles, OCV fits, flux maps, all
copied into the repository with their sources: data/*/SOURCES.md), the repository and its default
build folder. Nothing here points outside the repository: a clone runs alone.

The package runs from a clone (installed editable, `pip install -e .`) or from the wheel
(build/dist/ipmsm_fmu-<version>-py3-none-any.whl, no repository). The repository's files the
Python side reads beyond the package (the FMUs and the SSP package in build/, the default flux
map and the coupling description in fmu_src/) travel in the wheel under SHIPPED_DIR at their
repository paths; `located` is the one lookup that finds them either way."""
from __future__ import annotations

from pathlib import Path

#: the installed package
PACKAGE_DIR = Path(__file__).resolve().parents[1]

#: the repository (the package is installed editable, `pip install -e .`); in an installed wheel,
#: the folder the package is installed in (site-packages), which holds none of the repository
ROOT = PACKAGE_DIR.parent

#: an installed wheel's copies of the repository files the package reads, at their repository
#: paths (build/fmu/*.fmu, build/fmu3/*.fmu, build/ssp/*.ssp, fmu_src/resources/...,
#: fmu_src/coupling/...); absent in a clone (the wheel's build puts it into its staging copy
#: only, cmake/wheel.cmake)
SHIPPED_DIR = PACKAGE_DIR / "shipped"

#: True when running from an installed wheel rather than from a clone
FROM_WHEEL = SHIPPED_DIR.is_dir()

#: the repository's files outside the package that the package reads (build/: what `--build`
#: defaults to), which the wheel ships under SHIPPED_DIR (tools/wheel/make_wheel.py)
SHIPPED = ("build/fmu/IpmsmController.fmu", "build/fmu/IpmsmPlant.fmu", "build/fmu/IpmsmDrive.fmu",
           # the FMI 3.0 FMUs (`fmu-path NAME --fmi 3`, `run --fmi 3`)
           "build/fmu3/IpmsmController.fmu", "build/fmu3/IpmsmPlant.fmu", "build/fmu3/IpmsmDrive.fmu",
           "build/ssp/IpmsmControllerPlant.ssp", "fmu_src/resources/ev_ipmsm_default.csv",
           "fmu_src/coupling/ipmsm_drive.coupling", "docs/motor/efficiency_map.json",
           # the FMUs' parameter ranges and flux-map rules, as the C++ declares them (core/fmu_ranges.py)
           "modelDescription.xml", "plant/modelDescription.xml", "fmu_src/machine/map_rules.json")


def located(path: str | Path) -> Path:
    """A repository file by its path (absolute, or relative to the repository's root): itself
    in a clone; in an installed wheel, the wheel's copy (SHIPPED_DIR + the path below ROOT) where
    the wheel has one. Paths outside the repository are returned unchanged."""
    p = Path(path)
    p = p if p.is_absolute() else ROOT / p
    if FROM_WHEEL:
        try:
            shipped = SHIPPED_DIR / p.resolve().relative_to(ROOT)
        except ValueError:  # not below ROOT: the user's own file
            return p
        if shipped.exists():
            return shipped
    return p


#: the CMake build folder the scenarios take the FMUs (fmu/) and the SSP package (ssp/) from; in
#: an installed wheel, the wheel's copies
BUILD_DIR = located("build")

#: the FMUs' folder in a build, by FMI version: build/fmu (FMI 2.0), build/fmu3 (FMI 3.0), the same
#: three FMUs with the same variables and value references (issue 36)
FMU_FOLDERS = {2: "fmu", 3: "fmu3"}


def fmu_folder(build: Path = BUILD_DIR, fmi: int = 2) -> Path:
    """The folder of the build's FMUs of FMI version fmi (2 or 3)."""
    return Path(build) / FMU_FOLDERS[fmi]


#: where results go by default: out/ in the repository; from a wheel, out/ in the current folder
OUT_DIR = Path("out") if FROM_WHEEL else ROOT / "out"

#: the data the scenarios run on, shipped inside the package: cycles/, fluxmaps/ (fluxmaps/real/:
#: real published maps as published), ocv_nmc_cell_and_96s.csv; each folder's SOURCES.md says
#: where every file came from
DATA_DIR = PACKAGE_DIR / "data"
