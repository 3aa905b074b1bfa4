"""The project's commands as the README writes them: `./test.sh -m slow`, `./test.sh -k foo` (the
arguments go to pytest and to nothing else: the set-up scripts are sourced and would see them),
and `./run.sh --cycles ...` (to the study). Run on copies of the scripts beside stubs that record
what each step was given."""
from __future__ import annotations

import shutil
import subprocess

import pytest

from conftest import ROOT, patient

STEPS = ("setup.sh", "sanitize.sh", "lint.sh")  # scripts/ of test.sh and run.sh
COMMANDS = ("ctest", "python")                  # on PATH once the set-up has run


def _run(tmp_path, script: str, *args: str, lint_status: int = 0) -> list[str]:
    """Run a copy of `script` with stubbed steps; the lines the steps logged ("name: argc: args").
    The script must succeed, unless the lint stub is told to fail (then the script must fail)."""
    log = tmp_path / "log"
    (tmp_path / "scripts").mkdir()
    (tmp_path / "bin").mkdir()
    shutil.copy(ROOT / script, tmp_path / script)
    for name in STEPS:
        # setup.sh is sourced: it sees the caller's positional parameters unless the caller cleared them
        extra = f'export PATH="{tmp_path / "bin"}:$PATH"\n' if name == "setup.sh" else ""
        extra += f"exit {lint_status}\n" if name == "lint.sh" else ""
        (tmp_path / "scripts" / name).write_text(f'echo "{name}: $#: $*" >> "{log}"\n{extra}')
    for name in COMMANDS:
        stub = tmp_path / "bin" / name
        stub.write_text(f'#!/bin/sh\necho "{name}: $#: $*" >> "{log}"\n')
        stub.chmod(0o755)
    r = subprocess.run(["bash", str(tmp_path / script), *args], timeout=patient(60), capture_output=True, text=True)
    assert (r.returncode == 0) == (lint_status == 0), (r.returncode, r.stderr)
    return log.read_text().splitlines()


def _pytest_line(lines: list[str]) -> str:
    calls = [line for line in lines if line.startswith("python: ") and "-m pytest" in line]
    assert len(calls) == 1, lines
    return calls[0]


@pytest.mark.parametrize("args, pytest_args", [
    ((), "-m pytest tests/python -m not slow"),
    (("-m", "slow"), "-m pytest tests/python -m slow"),
    (("-k", "conformance", "-x"), "-m pytest tests/python -m not slow -k conformance -x"),
    (("-m", "slow or not slow", "-q"), "-m pytest tests/python -m slow or not slow -q"),
])
def test_test_sh_gives_its_arguments_to_pytest_only(tmp_path, args, pytest_args):
    lines = _run(tmp_path, "test.sh", *args)
    assert "setup.sh: 0: " in lines, lines
    assert "lint.sh: 0: " in lines, lines
    assert _pytest_line(lines).endswith(pytest_args), lines


def test_run_sh_gives_its_arguments_to_the_study_only(tmp_path):
    lines = _run(tmp_path, "run.sh", "--cycles", "WLTC3b", "UDDS")
    assert "setup.sh: 0: " in lines, lines
    assert "python: 5: -m scenarios sweep --out out/sweep" in lines, lines
    assert "python: 8: -m scenarios compare --out out/compare --cycles WLTC3b UDDS" in lines, lines


def test_setup_sources_the_vdmcheck2_installer_with_its_default_destination():
    """install_vdmcheck2.sh takes $1 as its destination: setup.sh passes it explicitly (empty: the
    default), so a caller's arguments can never reach it."""
    text = (ROOT / "scripts" / "setup.sh").read_text()
    sources = [line.strip() for line in text.splitlines() if line.strip().startswith("source ")]
    assert 'source scripts/install_vdmcheck2.sh ""' in sources, sources
    for line in sources:  # every sourced script gets explicit arguments, never the caller's
        assert line.split("#")[0].strip().endswith('""'), line


def test_a_lint_failure_fails_test_sh_after_the_tests_ran(tmp_path):
    lines = _run(tmp_path, "test.sh", lint_status=1)
    assert any(line.startswith("ctest: ") for line in lines), lines
    assert _pytest_line(lines).endswith("-m pytest tests/python -m not slow"), lines
