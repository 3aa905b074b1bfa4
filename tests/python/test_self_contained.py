"""The repository runs alone: a standard cycle runs with nothing outside the repository readable
(an audit hook refuses every open beside it, `../shared` included), and the data the package
carries are the files handed over in `../shared`, byte for byte, where that folder is present."""
from __future__ import annotations

import filecmp
import json
import subprocess
import sys
import textwrap

import pytest

from scenarios.core import paths

from conftest import ROOT

SHARED = ROOT.parent / "shared"

# In the child: any open of a path beside the repository (its parent folder, ../shared, ...) fails.
GUARD = textwrap.dedent("""
    import os, sys
    root = os.path.realpath({root!r})
    outside = os.path.realpath(os.path.join(root, os.pardir))
    def guard(event, args):
        if event == "open" and isinstance(args[0], (str, bytes, os.PathLike)):
            p = os.path.realpath(os.fsdecode(args[0]))
            if p.startswith(outside + os.sep) and not (p == root or p.startswith(root + os.sep)):
                raise PermissionError(f"outside the repository: {{p}}")
    sys.addaudithook(guard)
    import runpy
    sys.argv = ["scenarios"] + sys.argv[1:]
    runpy.run_module("scenarios", run_name="__main__", alter_sys=True)
""")


def test_a_standard_cycle_runs_with_nothing_beside_the_repository(tmp_path):
    out = tmp_path / "udds"
    code = GUARD.format(root=str(ROOT))
    r = subprocess.run([sys.executable, "-c", code, "run", "UDDS", "--backend", "drive", "--out", str(out)],
                       capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["cycle"] == "UDDS" and summary["distance_km"] > 11.0


def test_the_guard_refuses_what_lies_beside_the_repository(tmp_path):
    """The guard above can fail: reading a file beside the repository is refused."""
    beside = ROOT.parent / f".{ROOT.name}-guard-probe"
    code = GUARD.format(root=str(ROOT)).replace("import runpy", f"open({str(beside)!r}, 'w')\nimport runpy")
    r = subprocess.run([sys.executable, "-c", code, "--version"], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "outside the repository" in r.stderr
    assert not beside.exists()


@pytest.mark.skipif(not SHARED.is_dir(), reason="no ../shared beside this clone: nothing to compare with")
@pytest.mark.parametrize("copy, handed_over", [
    (paths.DATA_DIR / "cycles", SHARED / "data" / "cycles"),
    (paths.DATA_DIR / "fluxmaps", SHARED / "data" / "fluxmaps"),
    (paths.DATA_DIR / "ocv_nmc_cell_and_96s.csv", SHARED / "data" / "ocv_nmc_cell_and_96s.csv"),
    (ROOT / "docs" / "spec" / "MATH.md", SHARED / "spec" / "MATH.md"),
])
def test_the_copies_are_the_files_handed_over(copy, handed_over):
    if handed_over.is_file():
        assert filecmp.cmp(copy, handed_over, shallow=False), f"{copy} differs from {handed_over}"
        return
    cmp = filecmp.dircmp(handed_over, copy)
    stack = [cmp]
    while stack:
        c = stack.pop()
        assert not c.left_only, f"{c.left}: not copied: {c.left_only}"
        _, mismatch, errors = filecmp.cmpfiles(c.left, c.right, c.common_files, shallow=False)
        assert not mismatch and not errors, f"{c.left}: differ from the copy: {mismatch + errors}"
        stack.extend(c.subdirs.values())


@pytest.mark.skipif(not SHARED.is_dir(), reason="no ../shared beside this clone: nothing to compare with")
def test_the_contract_extends_the_one_handed_over():
    """docs/spec/INTERFACE.md may grow (new variables, keys, sections) but keeps every section and
    every name of the contract handed over."""
    import re
    ours, theirs = (p.read_text() for p in (ROOT / "docs" / "spec" / "INTERFACE.md", SHARED / "spec" / "INTERFACE.md"))
    headings = [line for line in theirs.splitlines() if line.startswith("#")]
    assert [h for h in headings if h not in ours.splitlines()] == []
    names = set(re.findall(r"`([^`\n]+)`", theirs))
    assert sorted(n for n in names if n not in ours) == []
