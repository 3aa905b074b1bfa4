"""Builds the wheel: DIST/ipmsm_fmu-<version>-py3-none-any.whl (CMake target `wheel`, cmake/wheel.cmake).

    python tools/wheel/make_wheel.py BUILD_DIR DIST_DIR

The wheel is the scenarios package with its data (pyproject.toml's package-data) plus the
repository files it reads beyond itself (scenarios.core.paths.SHIPPED: the three FMUs as built,
with their linux64 and win64 binaries, the SSP package, the default flux map, the coupling
description) under scenarios/shipped/ at their repository paths, where scenarios.core.paths.located
finds them; the OSP structure's FMU sources point there. It holds no compiled code outside the
FMUs: pure Python, any platform (py3-none-any). setuptools (pyproject.toml's build backend)
builds it from a staging copy in BUILD_DIR/wheel/, so the clone's own tree never holds a
shipped/ folder.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from scenarios.core.paths import SHIPPED  # noqa: E402
from scenarios.core.version import VERSION  # noqa: E402

#: the project files setuptools reads besides the package (pyproject.toml names README.md)
PROJECT_FILES = ("pyproject.toml", "README.md", "CHANGELOG.md")
#: the OSP structure, and its FMUs' sources relative to it in a clone and in the wheel
OSP_STRUCTURE = "scenarios/cosim/osp/OspSystemStructure.xml"
OSP_SOURCES_IN_CLONE = 'source="../../../build/fmu/'
OSP_SOURCES_IN_WHEEL = 'source="../../shipped/build/fmu/'
#: not shipped: caches
IGNORED = shutil.ignore_patterns("__pycache__", "*.pyc", "shipped")


def wheel_name() -> str:
    return f"ipmsm_fmu-{VERSION}-py3-none-any.whl"


def stage(build: Path, staging: Path) -> None:
    """The wheel's source tree: the package, its project files and the shipped copies."""
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    for name in PROJECT_FILES:
        shutil.copy2(ROOT / name, staging / name)
    shutil.copytree(ROOT / "scenarios", staging / "scenarios", ignore=IGNORED)
    # the OSP structure's FMU sources, relative to it: the build's in a clone, the wheel's copies here
    osp = staging / OSP_STRUCTURE
    text = osp.read_text()
    if text.count(OSP_SOURCES_IN_CLONE) != 2:
        raise SystemExit(f"make_wheel: {OSP_STRUCTURE} names its FMUs other than as {OSP_SOURCES_IN_CLONE}...")
    osp.write_text(text.replace(OSP_SOURCES_IN_CLONE, OSP_SOURCES_IN_WHEEL))
    for rel in SHIPPED:
        parts = Path(rel).parts
        src = build.joinpath(*parts[1:]) if parts[0] == "build" else ROOT / rel
        if not src.is_file():
            raise SystemExit(f"make_wheel: {src} is missing (build it first: cmake --build {build})")
        dest = staging / "scenarios" / "shipped" / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, dest)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("build", type=Path, help="the CMake build folder (fmu/, ssp/)")
    ap.add_argument("dist", type=Path, help="where the wheel goes")
    a = ap.parse_args(argv)
    build, dist = a.build.resolve(), a.dist.resolve()
    staging = build / "wheel" / "src"
    stage(build, staging)
    dist.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=build / "wheel") as tmp:
        # no isolation: the build uses the venv's setuptools (pyproject.toml's requires), no download
        subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
                        "--wheel-dir", tmp, str(staging)], check=True)
        (built,) = Path(tmp).glob("*.whl")
        if built.name != wheel_name():
            raise SystemExit(f"make_wheel: setuptools built {built.name}, expected {wheel_name()}")
        for old in dist.glob("ipmsm_fmu-*.whl"):
            old.unlink()
        shutil.move(str(built), dist / built.name)
    shutil.rmtree(staging / "build", ignore_errors=True)  # setuptools' own build/ in the staging copy
    print(f"make_wheel: wrote {dist / wheel_name()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
