"""From a study's runs to the tasks to execute: each run's cycle (window applied), RunSpec and
key (scenarios.study.keys); runs whose key is "ok" in runs.parquet already are left out."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..cycles import Cycle, load_cycle, segment
from ..drive_description import DriveDescription, load_drive
from ..simulate import RunSpec
from . import keys
from .execute import Task
from .spec import Run


@dataclass(frozen=True)
class Plan:
    keys: tuple[str, ...]         # every run's key, in the spec's order
    tasks: tuple[Task, ...]       # to run
    skipped: int                  # already "ok"
    failed_rows: tuple[dict, ...]  # runs that could not even be set up (recorded as failed)


def run_spec(run: Run, drive: DriveDescription | None = None) -> RunSpec:
    """The simulation's specification of a run (its drive loaded already, or loaded here)."""
    drive = drive if drive is not None else load_drive(run.drive or None)
    return RunSpec(drive=drive, method=run.method, recursion=run.recursion, conditions=run.conditions())


def run_cycle(run: Run, cache: dict) -> Cycle:
    if run.cycle not in cache:
        cache[run.cycle] = load_cycle(run.cycle)
    c = cache[run.cycle]
    return segment(c, *run.window) if run.window else c


def key_columns(run: Run) -> dict:
    """The run's columns as they enter its key: files by name only (their content enters apart),
    so a study moved to another folder keeps its keys."""
    d = run.to_dict()
    d["drive"] = Path(run.drive).name if run.drive else ""
    d["cycle"] = Path(run.cycle).name
    return d


def make_plan(runs, out: Path, fmu_hash: str, code_hash: str, done: set[str]) -> Plan:
    from . import table
    all_keys, tasks, failed, skipped, cycles = [], [], [], 0, {}
    for run in runs:
        cycle = run_cycle(run, cycles)
        content = dict(cycle=keys.cycle_hash(cycle))
        key = keys.run_key(key_columns(run), content, fmu_hash, code_hash)
        all_keys.append(key)
        if key in done:
            skipped += 1
            continue
        try:
            spec = run_spec(run)
        except Exception as e:  # a drive description that does not load: this run fails, not the study
            failed.append(table.row_of(run, dict(key=key, status="failed", error=f"{type(e).__name__}: {e}",
                                                 fmu_hash=fmu_hash, code_hash=code_hash), None))
            continue
        tasks.append(Task(key, run, cycle, spec, str(Path(out).resolve()), fmu_hash, code_hash))
    return Plan(tuple(all_keys), tuple(tasks), skipped, tuple(failed))
