"""From a study's runs to the tasks to execute: each run's cycle (window applied), drive (loaded
and shipped with its files) and key (scenarios.study.keys); runs whose key is "ok" in
runs.parquet already are left out, runs whose drive does not load are failed rows at once."""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from scenarios.drives.description import load_drive
from scenarios.drives.fmu_acceptance import refuse_unless_fmus_accept
from scenarios.study import keys, table
from scenarios.study.execute import Task
from scenarios.study.ship import ShippedDrive
from scenarios.study.spec import Run
from scenarios.vehicle.cycles import Cycle, load_cycle, segment


@dataclass(frozen=True)
class Plan:
    keys: tuple[str, ...]          # every run's key, in the spec's order
    tasks: tuple[Task, ...]        # to run
    drives: dict                   # Run.drive -> ShippedDrive, of the tasks
    skipped: int                   # already "ok"
    failed_rows: tuple[dict, ...]  # runs whose drive does not load (recorded as failed)


def run_cycle(run: Run, cache: dict) -> Cycle:
    if run.cycle not in cache:
        cache[run.cycle] = load_cycle(run.cycle)
    c = cache[run.cycle]
    return segment(c, *run.window) if run.window else c


def load_shipped(drive: str, build: Path | None = None) -> ShippedDrive | Exception:
    """The drive ("" the default) with its files, or why it cannot be used: it does not load, or
    (with `build`) the FMUs there refuse its map and motor, in their own words."""
    try:
        loaded = load_drive(drive or None)
        if build is not None:
            refuse_unless_fmus_accept(loaded, build)
        return ShippedDrive.of(loaded)
    except Exception as e:  # a drive that does not load fails its runs, not the study
        return e


def drive_content(drive: str, shipped: ShippedDrive | Exception) -> str:
    if isinstance(shipped, ShippedDrive):
        return shipped.content_hash()
    if not drive:
        return "default:unloadable"
    h = hashlib.sha256()
    try:  # streamed: a drive that did not load may be any file (a 2 GB one is not read into memory)
        with open(drive, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError as e:  # a folder, a vanished file: its key names why
        h.update(f"unreadable: {e.strerror}".encode())
    return h.hexdigest()


def key_columns(run: Run) -> dict:
    """The run's columns as they enter its key: files by name only (their content enters apart),
    so a study moved to another folder keeps its keys."""
    d = run.to_dict()
    d["drive"] = Path(run.drive).name if run.drive else ""
    d["cycle"] = Path(run.cycle).name
    return d


def make_plan(runs, out: Path, fmu_hash: str, code_hash: str, done: set[str], build: Path | None = None) -> Plan:
    """The study's plan: every run's key, what is left to run, and the runs of drives that cannot
    be used (recorded as failed). build: the FMUs that judge each drive's map (None: not asked)."""
    all_keys, tasks, failed, skipped, cycles, drives = [], [], [], 0, {}, {}
    for run in runs:
        cycle = run_cycle(run, cycles)
        if run.drive not in drives:
            drives[run.drive] = load_shipped(run.drive, build)
        shipped = drives[run.drive]
        content = dict(cycle=keys.cycle_hash(cycle), drive=drive_content(run.drive, shipped))
        key = keys.run_key(key_columns(run), content, fmu_hash, code_hash)
        all_keys.append(key)
        if key in done:
            skipped += 1
        elif isinstance(shipped, Exception):
            failed.append(table.row_of(run, dict(key=key, status="failed", error=f"{type(shipped).__name__}: {shipped}",
                                                 fmu_hash=fmu_hash, code_hash=code_hash,
                                                 condition=run.conditions().name), None))
        else:
            tasks.append(Task(key, run, cycle, str(Path(out).resolve()), fmu_hash, code_hash))
    used = {t.run.drive for t in tasks}
    return Plan(tuple(all_keys), tuple(tasks), {d: s for d, s in drives.items() if d in used}, skipped,
                tuple(failed))
