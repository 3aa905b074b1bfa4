"""The repository runs alone: a standard cycle runs with nothing outside the repository readable
(an audit hook refuses every open beside it, `../shared` included), and the data the package
carries are the files handed over in `../shared`, byte for byte (their digests are committed, so a
clone alone checks them too)."""
from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from scenarios.core import paths
from scenarios.vehicle.cycles import cycle_stats, load_cycle, segment

from conftest import ROOT, patient

SHARED = ROOT.parent / "shared"
HANDED_OVER = json.loads((ROOT / "tests" / "data" / "handed_over.json").read_text())
#: a copy's top folder in the repository, above the path it had in ../shared (data/..., spec/...)
COPIED_FROM = {"scenarios": ("scenarios",), "docs": ("docs",)}

# In the child: any open of a path beside the repository (its parent folder, ../shared, ...) fails,
# but for the build and the run's own output folder (which may lie beside a clone in /tmp).
GUARD = textwrap.dedent("""
    import os, sys
    root = os.path.realpath({root!r})
    outside = os.path.realpath(os.path.join(root, os.pardir))
    build = os.path.realpath({build!r})  # the build may be a link (a shared build of this clone)
    out = os.path.realpath({out!r})
    def within(p, folder):
        return p == folder or p.startswith(folder + os.sep)
    def guard(event, args):
        if event == "open" and isinstance(args[0], (str, bytes, os.PathLike)):
            p = os.path.realpath(os.fsdecode(args[0]))
            inside = within(p, root) or within(p, build) or within(p, out)
            if p.startswith(outside + os.sep) and not inside:
                raise PermissionError(f"outside the repository: {{p}}")
    sys.addaudithook(guard)
    import runpy
    sys.argv = ["scenarios"] + sys.argv[1:]
    runpy.run_module("scenarios", run_name="__main__", alter_sys=True)
""")


#: the default run drives the standard cycle's first seconds (its first two hills: standstill,
#: accelerating, braking): every file a run opens is opened before its first step or after its
#: last, so the guard sees the same opens as for the whole cycle (behind `slow`, below)
FIRST_PART_S = 120.0
# In the child, after the guard: the named cycle is loaded as always (its file, by its name), then
# cut to its first part under its own name.
FIRST_PART = textwrap.dedent("""
    import scenarios.vehicle.cycles as cycles
    whole = cycles.load_cycle
    def first_part(name):
        c = whole(name)
        s = cycles.segment(c, 0.0, {t1!r})
        return cycles.Cycle(c.name, s.time_s, s.speed_mps)
    cycles.load_cycle = first_part
    import runpy""")


def _guarded_run(tmp_path, first_part_s: float | None) -> dict:
    """`run UDDS` under the guard (the whole cycle, or its first part); the summary."""
    out = tmp_path / "udds"
    code = GUARD.format(root=str(ROOT), build=str(paths.BUILD_DIR), out=str(out))
    if first_part_s is not None:
        code = code.replace("import runpy", FIRST_PART.format(t1=first_part_s))
    r = subprocess.run([sys.executable, "-c", code, "run", "UDDS", "--backend", "drive", "--out", str(out)],
                       capture_output=True, text=True, timeout=patient(300), cwd=tmp_path)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["cycle"] == "UDDS"
    return summary


def test_a_standard_cycle_runs_with_nothing_beside_the_repository(tmp_path):
    summary = _guarded_run(tmp_path, FIRST_PART_S)
    km = cycle_stats(segment(load_cycle("UDDS"), 0.0, FIRST_PART_S))["distance_m"] / 1e3
    assert 0.95 * km < summary["distance_km"] < 1.05 * km  # the first part, all of it


@pytest.mark.slow
def test_the_whole_standard_cycle_runs_with_nothing_beside_the_repository(tmp_path):
    summary = _guarded_run(tmp_path, None)
    assert summary["distance_km"] > 11.0


def test_the_guard_refuses_what_lies_beside_the_repository(tmp_path):
    """The guard above can fail: reading a file beside the repository is refused."""
    beside = ROOT.parent / f".{ROOT.name}-guard-probe"
    code = GUARD.format(root=str(ROOT), build=str(paths.BUILD_DIR), out=str(tmp_path / "out"))
    code = code.replace("import runpy", f"open({str(beside)!r}, 'w')\nimport runpy")
    r = subprocess.run([sys.executable, "-c", code, "--version"], capture_output=True, text=True,
                       timeout=patient(60))
    assert r.returncode != 0 and "outside the repository" in r.stderr
    assert not beside.exists()


def _sha256(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_the_copies_are_the_files_handed_over():
    """Every data file and MATH.md as handed over, byte for byte (their SHA-256, committed in
    tests/data/handed_over.json), and nothing handed over left out. MATH.md grows: the project
    derives its new equations there, after the text handed over, which stays as it was."""
    for rel, digest in HANDED_OVER["files"].items():
        assert (ROOT / rel).is_file(), f"{rel}: handed over, not in the repository"
        size = HANDED_OVER.get("grows", {}).get(rel)
        data = (ROOT / rel).read_bytes()
        kept = data if size is None else data[:size]
        assert hashlib.sha256(kept).hexdigest() == digest, f"{rel} differs from the file handed over"


@pytest.mark.skipif(not SHARED.is_dir(), reason="no ../shared beside this clone: the committed record stands")
def test_the_committed_record_is_what_shared_holds():
    """Where ../shared is present: the record above is still what it holds."""
    for rel, digest in HANDED_OVER["files"].items():
        src = SHARED / Path(rel).relative_to(*COPIED_FROM[Path(rel).parts[0]])
        assert _sha256(src) == digest, f"{src} changed since it was handed over: copy it in again"


def test_the_contract_extends_the_one_handed_over():
    """docs/spec/INTERFACE.md may grow (new variables, keys, sections) but keeps every section and
    every name of the contract handed over (tests/data/handed_over.json). Names that are paths
    relative to the handed-over folder (`../data/...`) point, in the repository, to the copies."""
    ours = (ROOT / "docs" / "spec" / "INTERFACE.md").read_text()
    assert [h for h in HANDED_OVER["interface_headings"] if h not in ours.splitlines()] == []
    names = [n for n in HANDED_OVER["interface_names"] if not n.startswith("../")]
    assert sorted(n for n in names if n not in ours) == []
