"""Running a study's runs on dask.distributed.

The cluster: by default an embedded LocalCluster on 127.0.0.1, one single-threaded worker
process per core (the FMUs and the co-simulation hold the GIL: processes, not threads), or any
existing cluster by its scheduler's address.

What travels (scenarios.study.ship): the FMUs are *shipped*: the client reads the build's three
.fmu once and scatters them to every worker, which
unpacks them once; so the FMUs that ran are exactly the ones whose hash is in the rows, whatever
is installed on the workers. Each drive description travels loaded, with its flux map and OCV
curve, once per drive; each task carries its cycle's samples, not paths. The workers need the
same Python package (`pip install` of this repository; the client checks its code hash on every
worker) and write the traces to `DIR/traces/` themselves, so DIR must be the same path for them
(a shared filesystem on a cluster); only the summary row comes back to the client.

Faults: a run that raises is a result (status "failed", its message), not a task failure, and
is not retried (it would fail again). A worker that dies makes the scheduler run its task on
another worker, up to `distributed.scheduler.allowed-failures` deaths (ALLOWED_WORKER_DEATHS
here for the embedded cluster; the scheduler's own configuration for an external one), after
which the run is recorded failed ("KilledWorker").
"""
from __future__ import annotations

import os
import shutil
import signal
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from scenarios.runs.simulate import fmu_paths, simulate
from scenarios.study import table
from scenarios.study.ship import FmuBundle, ShippedDrive
from scenarios.study.spec import Run, run_spec
from scenarios.vehicle.cycles import Cycle

#: how often a run may lose its worker before it is recorded failed (distributed's default)
ALLOWED_WORKER_DEATHS = 3

#: fault injection for the tests: the first run to start (anywhere) whose worker sees this
#: variable creates the file it names and SIGKILLs its own worker process before returning
KILL_ONCE_ENV = "IPMSM_STUDY_KILL_ONCE"


@dataclass(frozen=True)
class Task:
    """What a worker needs for one run."""

    key: str
    run: Run
    cycle: Cycle          # the samples to drive (window applied)
    out: str              # the study's folder (traces/ in it)
    fmu_hash: str
    code_hash: str


def _worker_address() -> str:
    try:
        from distributed import get_worker
        return get_worker().address
    except (ImportError, ValueError):
        return f"local-{os.getpid()}"


def _kill_once_hook() -> None:
    marker = os.environ.get(KILL_ONCE_ENV)
    if not marker:
        return
    try:
        os.close(os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return
    os.kill(os.getpid(), signal.SIGKILL)


def run_task(task: Task, bundle: FmuBundle, drive: ShippedDrive) -> dict:
    """One run on a worker: simulate, write the trace to DIR/traces/<key>.parquet, return the
    row. An error of the run is returned as a failed row, with its message."""
    started, t0 = time.time(), time.perf_counter()
    meta = dict(key=task.key, fmu_hash=task.fmu_hash, code_hash=task.code_hash, worker=_worker_address(),
                started_utc=started, condition=task.run.conditions().name)
    scratch = Path(tempfile.mkdtemp(prefix=f"run-{task.key}-"))
    try:
        build = bundle.materialise()
        spec = run_spec(task.run, drive.localise())
        summary = simulate(task.cycle, spec, fmus=fmu_paths(build), out=scratch, progress=False)
        table.write_trace_parquet(scratch / "trace.csv", table.trace_path(Path(task.out), task.key))
        _kill_once_hook()
        meta.update(status="ok", error=None, run_wall_s=time.perf_counter() - t0)
        return table.row_of(task.run, meta, summary)
    except Exception as e:  # the run's own failure: recorded, the study goes on
        meta.update(status="failed", error=f"{type(e).__name__}: {e}", run_wall_s=time.perf_counter() - t0)
        return table.row_of(task.run, meta, None)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
