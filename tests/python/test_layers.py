"""The scenarios package's architecture (scenarios/README.md): subpackages in layers, each
importing only itself and the layers below it; the command line (`__main__`) on top."""
from __future__ import annotations

import ast

import pytest

from scenarios.core.paths import PACKAGE_DIR

#: lowest first
LAYERS = ("core", "cosim", "vehicle", "maps", "drives", "runs", "study")


def _imports(path) -> set[str]:
    """The scenarios modules a file imports (absolute names; relative imports resolved)."""
    rel = path.relative_to(PACKAGE_DIR).with_suffix("").parts
    package = ["scenarios", *rel[:-1]]
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
            names.update([base] if base else [])
            names.update(f"{base}.{a.name}" for a in node.names)
    return {n for n in names if n == "scenarios" or n.startswith("scenarios.")}


def _layer(module: str) -> int | None:
    parts = module.split(".")
    return LAYERS.index(parts[1]) if len(parts) > 1 and parts[1] in LAYERS else None


def _modules():
    return sorted(p for p in PACKAGE_DIR.rglob("*.py") if p.relative_to(PACKAGE_DIR).parts[0] in LAYERS)


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE_DIR)))
def test_no_module_imports_upward(path):
    own = LAYERS.index(path.relative_to(PACKAGE_DIR).parts[0])
    upward = sorted(m for m in _imports(path) if m in ("scenarios", "scenarios.__main__")
                    or (_layer(m) is not None and _layer(m) > own))
    assert not upward, f"{path.relative_to(PACKAGE_DIR)} imports a layer above its own: {upward}"


def test_every_module_is_in_a_layer():
    top = sorted(p.name for p in PACKAGE_DIR.glob("*.py"))
    assert top == ["__init__.py", "__main__.py"], f"modules outside the layers: {top}"
    folders = sorted(p.name for p in PACKAGE_DIR.iterdir() if p.is_dir() and not p.name.startswith("__"))
    assert set(folders) - {"data"} <= set(LAYERS), folders
