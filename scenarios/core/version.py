"""The project's one version number: pyproject.toml's (CHANGELOG.md says what each version changed
for users). The FMUs carry it in their modelDescription's `version` (CMakeLists.txt reads the same
line), and so do `python -m scenarios --version`, every summary.json and every runs.parquet row."""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from scenarios.core.paths import FROM_WHEEL, ROOT

#: the distribution's name (pyproject.toml [project] name)
DISTRIBUTION = "ipmsm-fmu"


def _version() -> str:
    # In a clone, pyproject.toml itself: an editable install's metadata is as old as its install.
    pyproject = ROOT / "pyproject.toml"
    if not FROM_WHEEL and pyproject.is_file():
        import tomllib
        return tomllib.loads(pyproject.read_text())["project"]["version"]
    try:
        return version(DISTRIBUTION)
    except PackageNotFoundError:
        return "unknown"


VERSION = _version()
