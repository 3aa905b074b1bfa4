"""A study from its runs to DIR/runs.parquet: plan (keys, skip what is done), execute on a
dask.distributed cluster with a bounded number of runs in flight, record each row as it comes
back, consolidate.

    from scenarios.study import load_spec, run_study
    result = run_study(load_spec("study.toml").runs, Path("out/study"), workers=2)
"""
from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa

from scenarios.core.paths import BUILD_DIR
from scenarios.study import keys, table
from scenarios.study.execute import ALLOWED_WORKER_DEATHS, run_task
from scenarios.study.plan import make_plan
from scenarios.study.progress import StudyProgress
from scenarios.study.ship import FmuBundle
from scenarios.study.spec import Run

#: runs in flight per worker thread: enough to keep every worker busy between two results,
#: few enough that the scheduler holds a bounded number of tasks whatever the study's size
IN_FLIGHT_PER_THREAD = 2


#: s, how long a study waits for the first worker of an existing cluster (a batch system may be slow)
WORKER_WAIT_S = 600


#: s, how long connecting to an existing scheduler and its first words may take
CONNECT_TIMEOUT_S = 20.0
#: bytes: a dask comm's handshake is a few hundred; a peer announcing more is no dask scheduler
HANDSHAKE_MAX_BYTES = 1 << 20


class StudyError(RuntimeError):
    """The study cannot run at all (no FMUs, workers with other code, no scheduler)."""


def scheduler_address(address: str) -> tuple[str, int]:
    """(host, port) of a tcp://host:port address; anything else: InputError (exit 2)."""
    from urllib.parse import urlsplit

    from scenarios.core.boundary import InputError
    try:
        u = urlsplit(address)
        port = u.port
    except ValueError:
        port = None
        u = None
    if u is None or u.scheme != "tcp" or not u.hostname or port is None or u.path not in ("", "/"):
        raise InputError("(command line)", "--scheduler", f"the address of a running dask scheduler, "
                         f"tcp://HOST:PORT, got {address!r}")
    return u.hostname, port


def probe_scheduler(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Before distributed's Client (which waits without end for a peer that accepts and never
    speaks, and allocates whatever length a stranger's first 8 bytes announce): connect, read the
    peer's handshake frame header within `timeout` and check it is one a scheduler sends."""
    import socket
    import struct
    host, port = scheduler_address(address)
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            sock.settimeout(timeout)
            head = b""
            while len(head) < 8:
                b = sock.recv(8 - len(head))
                if not b:
                    raise StudyError(f"the server at {address} closed the connection: not a dask scheduler")
                head += b
    except TimeoutError:
        raise StudyError(f"the server at {address} did not answer within {timeout:g} s: "
                         "not a dask scheduler, or one that hangs") from None
    except OSError as e:
        raise StudyError(f"no dask scheduler at {address}: {e.strerror or e}") from None
    (n,) = struct.unpack("<Q", head)
    if not 0 < n <= HANDSHAKE_MAX_BYTES:
        raise StudyError(f"the server at {address} does not speak dask's protocol (its first frame announces "
                         f"{n} bytes)")


@dataclass(frozen=True)
class StudyResult:
    table: pa.Table      # runs.parquet after the study (every row, also of earlier studies)
    keys: tuple[str, ...]  # the keys of this study's runs, in the spec's order
    executed: int        # runs executed now
    skipped: int         # runs already "ok"
    failed: int          # runs of this study recorded failed now


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


@contextlib.contextmanager
def open_client(scheduler: str | None, workers: int | None, n_runs: int):
    """A distributed Client: on `scheduler`'s cluster, or on an embedded LocalCluster."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        probe_scheduler(scheduler)
        try:
            client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
        except (OSError, TimeoutError) as e:
            raise StudyError(f"no dask scheduler at {scheduler}: {e}") from None
        with client:
            try:
                client.wait_for_workers(1, timeout=WORKER_WAIT_S)
            except TimeoutError:
                raise StudyError(f"the scheduler at {scheduler} has no worker after {WORKER_WAIT_S} s") from None
            yield client
        return
    n = min(workers or default_workers(), max(n_runs, 1))
    with dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_WORKER_DEATHS}), \
            LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                         dashboard_address="127.0.0.1:0") as cluster, Client(cluster) as client:
        yield client


def _check_workers(client, code: str) -> None:
    theirs = client.run(keys.code_hash)
    other = {w: h for w, h in theirs.items() if h != code}
    if other:
        w, h = next(iter(other.items()))
        raise StudyError(f"worker {w} runs other scenarios code (code hash {h}, the client's {code}): "
                         "install the same version on the workers")


def _same(x):
    return x


def run_study(runs: Sequence[Run], out: Path, scheduler: str | None = None, workers: int | None = None,
              build: Path = BUILD_DIR, progress: bool = True) -> StudyResult:
    """Run what is not done yet of `runs`; rows go to out/runs.parquet as they finish."""
    from distributed import as_completed
    from distributed.client import FutureCancelledError

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        bundle = FmuBundle.of(build)
    except FileNotFoundError as e:
        raise StudyError(str(e)) from None
    code = keys.code_hash()
    previous = table.consolidate(out)
    plan = make_plan(runs, out, bundle.hash, code, table.done_keys(previous), build)
    for row in plan.failed_rows:
        table.write_part(out, row)
    bar = StudyProgress(len(runs), plan.skipped) if progress else None
    ok, failed = 0, len(plan.failed_rows)
    try:
        if plan.tasks:
            with open_client(scheduler, workers, len(plan.tasks)) as client:
                _check_workers(client, code)
                # as tasks, not scattered data: a task's result lost with its worker is made again
                shipped = client.submit(_same, bundle, key=f"fmus-{bundle.hash}", pure=False)
                drives = {d: client.submit(_same, s, key=f"drive-{s.content_hash()[:16]}", pure=False)
                          for d, s in plan.drives.items()}
                threads = max(1, sum(client.nthreads().values()))
                pending = list(reversed(plan.tasks))
                running = as_completed()

                def submit_next():
                    t = pending.pop()
                    running.add(client.submit(run_task, t, shipped, drives[t.run.drive], key=f"run-{t.key}",
                                              pure=False))

                for _ in range(min(len(pending), IN_FLIGHT_PER_THREAD * threads)):
                    submit_next()
                by_key = {f"run-{t.key}": t for t in plan.tasks}
                for future in running:
                    try:
                        row = future.result()
                    except (Exception, FutureCancelledError) as e:  # KilledWorker after the allowed deaths
                        t = by_key[future.key]
                        row = table.row_of(t.run, dict(key=t.key, status="failed", fmu_hash=bundle.hash,
                                                       code_hash=code, condition=t.run.conditions().name,
                                                       error=f"{type(e).__name__}: {e}"), None)
                    future.release()
                    table.write_part(out, row)
                    ok += row["status"] == "ok"
                    failed += row["status"] != "ok"
                    if pending:
                        submit_next()
                    if bar:
                        bar.update(ok, failed, min(running.count(), threads))
    finally:
        if bar:
            bar.close()
    result = table.consolidate(out)
    return StudyResult(result, plan.keys, ok + failed, plan.skipped, failed)
