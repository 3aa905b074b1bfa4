"""A study's progress on stderr: runs done / running / failed and the time left (from the
mean time per finished run of this session), one line at most every `every_s` (a rewritten
line on a terminal)."""
from __future__ import annotations

import sys
import time


def _clock(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


class StudyProgress:
    def __init__(self, total: int, skipped: int, stream=None, every_s: float = 1.0):
        self.total, self.skipped = total, skipped
        self.done = self.failed = self.running = 0
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self.every = every_s
        self.t0 = time.perf_counter()
        self._last = -1e9

    def update(self, done: int, failed: int, running: int, force: bool = False) -> None:
        self.done, self.failed, self.running = done, failed, running
        now = time.perf_counter()
        if force or now - self._last >= self.every:
            self._last = now
            self.stream.write(("\r" if self.tty else "") + self.line() + ("" if self.tty else "\n"))
            self.stream.flush()

    def line(self) -> str:
        elapsed = time.perf_counter() - self.t0
        finished = self.done + self.failed
        left = self.total - self.skipped - finished
        eta = elapsed / finished * left if finished else float("nan")
        return (f"study: {self.skipped + finished}/{self.total} done ({self.skipped} before, {self.failed} failed), "
                f"{self.running} running, {_clock(elapsed)} elapsed, "
                f"{_clock(eta) if finished else '?'} left")

    def close(self) -> None:
        self.update(self.done, self.failed, 0, force=True)
        if self.tty:
            self.stream.write("\n")
