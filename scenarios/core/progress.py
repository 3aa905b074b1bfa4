"""A dependency-free progress bar for long runs (stderr; quiet when not a terminal, except a final line)."""
from __future__ import annotations

import sys
import time


class Progress:
    def __init__(self, total: int, label: str, every_s: float = 0.5):
        self.total, self.label, self.every = total, label, every_s
        self.n = 0
        self.t0 = self._last = time.perf_counter()
        self.tty = sys.stderr.isatty()

    def update(self, k: int = 1) -> None:
        self.n += k
        now = time.perf_counter()
        if self.tty and now - self._last >= self.every:
            self._last = now
            frac = self.n / self.total
            bar = "#" * int(30 * frac)
            eta = (now - self.t0) * (1 - frac) / frac if frac > 0 else 0
            sys.stderr.write(f"\r{self.label} [{bar:<30}] {100 * frac:5.1f}%  eta {eta:5.1f} s")
            sys.stderr.flush()

    def close(self) -> None:
        dt = time.perf_counter() - self.t0
        sys.stderr.write(("\r" if self.tty else "") + f"{self.label}: {self.n}/{self.total} done in {dt:.1f} s\n")
