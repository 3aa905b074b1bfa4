"""A dependency-free progress bar for long runs (stderr); not on a terminal (a log), a line every
LOG_EVERY_S of a long run and a final line."""
from __future__ import annotations

import sys
import time

#: s between two progress lines in a log (a run shorter than this prints only its final line)
LOG_EVERY_S = 30.0


class Progress:
    def __init__(self, total: int, label: str, every_s: float = 0.5):
        self.tty = sys.stderr.isatty()
        # the label names a cycle, a file: its escape sequences and controls are shown, not obeyed
        from scenarios.core.boundary import printable
        self.total, self.label, self.every = total, printable(label, limit=200), every_s if self.tty else LOG_EVERY_S
        self.n = 0
        self.t0 = self._last = time.perf_counter()

    def update(self, k: int = 1) -> None:
        self.n += k
        now = time.perf_counter()
        if now - self._last >= self.every:
            self._last = now
            frac = self.n / self.total
            eta = (now - self.t0) * (1 - frac) / frac if frac > 0 else 0
            if self.tty:
                bar = "#" * int(30 * frac)
                sys.stderr.write(f"\r{self.label} [{bar:<30}] {100 * frac:5.1f}%  eta {eta:5.1f} s")
            else:
                sys.stderr.write(f"{self.label}: {100 * frac:.0f} % after {now - self.t0:.0f} s, eta {eta:.0f} s\n")
            sys.stderr.flush()

    def close(self) -> None:
        dt = time.perf_counter() - self.t0
        sys.stderr.write(("\r" if self.tty else "") + f"{self.label}: {self.n}/{self.total} done in {dt:.1f} s\n")
