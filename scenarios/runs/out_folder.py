"""A run's output folder holds one run (docs/inputs.md, "Outputs"):

- before the run, every file it will write is one it may replace (a regular file or nothing;
  scenarios.core.boundary.output_target), so hours are never lost to a FIFO in the way;
- one run at a time: the folder's lock (flock on .run.lock, released when the process ends, even
  killed) refuses a second run into it;
- after the run, a file of another kind a previous run left (thermal.png beside a run without the
  thermal network) is removed: what the folder holds is this run's;
- a run that fails leaves no folder it made (an empty one is removed).
"""
from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from scenarios.core.boundary import InputError, check_outputs, check_writable

#: every file `run` may write into its folder
RUN_OUTPUTS = ("summary.json", "trace.csv", "run.png", "thermal.png", "fault_trace.csv", "fault.png")
#: the lock file (hidden: not a result)
LOCK_NAME = ".run.lock"


class RunFolder:
    """The folder of a run in progress; `done(written)` at its end removes the other outputs."""

    def __init__(self, path: Path, outputs: tuple[str, ...]):
        self.path, self.outputs = path, outputs

    def done(self, written) -> None:
        for name in set(self.outputs) - set(written):
            p = self.path / name
            try:
                if stat.S_ISREG(os.lstat(p).st_mode):
                    p.unlink()
            except FileNotFoundError:
                pass


def _lock(fd: int) -> bool:
    try:
        import fcntl
    except ImportError:  # no flock (Windows): no lock, as before
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except BlockingIOError:
        return False


@contextmanager
def run_folder(out: Path, outputs: tuple[str, ...] = RUN_OUTPUTS, what: str = "--out") -> Iterator[RunFolder]:
    """`out` made ready for one run (InputError, exit 2, before anything runs if it cannot be)."""
    out = Path(out)
    made = not os.path.lexists(out)
    check_writable(out, what)
    try:
        check_outputs(out, (*outputs, LOCK_NAME), what)
        lock = out / LOCK_NAME
        fd = os.open(lock, os.O_CREAT | os.O_RDWR | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0), 0o644)
    except BaseException:
        _remove_if_empty(out, made)
        raise
    ok = False
    try:
        if not _lock(fd) or _replaced(fd, lock):
            raise InputError(out, what, "a folder no other run is writing into (another run holds its lock "
                             f"{LOCK_NAME}: wait for it, or give another --out)")
        yield RunFolder(out, outputs)
        ok = True
    finally:
        try:
            os.unlink(lock)  # while held: the next run makes a new one
        except OSError:
            pass
        os.close(fd)
        if not ok:
            _remove_if_empty(out, made)


def _replaced(fd: int, lock: Path) -> bool:
    """The lock file was unlinked (its run ended) between our open and our lock: not ours."""
    try:
        return os.fstat(fd).st_ino != os.stat(lock).st_ino
    except OSError:
        return True


def _remove_if_empty(out: Path, made: bool) -> None:
    if made:
        try:
            out.rmdir()  # only if empty: a failed run leaves no folder it made
        except OSError:
            pass
