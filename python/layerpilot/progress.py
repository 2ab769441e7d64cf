"""A small terminal progress bar: long work says what it is doing and how far it got."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """Redraws one line on a terminal; prints occasional lines when output is not a terminal."""

    def __init__(self, total: float, label: str, unit: str = "", stream: TextIO | None = None) -> None:
        self.total = max(float(total), 1e-12)
        self.label = label
        self.unit = unit
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self._start = time.monotonic()
        self._last_print = -1.0

    def update(self, done: float, status: str = "") -> None:
        now = time.monotonic()
        finished = done >= self.total
        interval = 0.1 if self.tty else 5.0
        if not finished and now - self._last_print < interval:
            return
        self._last_print = now
        frac = min(max(done / self.total, 0.0), 1.0)
        bar = "#" * int(frac * 30)
        line = (
            f"{self.label} [{bar:<30}] {100 * frac:5.1f}% "
            f"{done:.0f}/{self.total:.0f}{self.unit} {now - self._start:5.1f}s {status}"
        )
        if self.tty:
            self.stream.write("\r" + line[:200].ljust(120))
            if finished:
                self.stream.write("\n")
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self, status: str = "") -> None:
        self._last_print = -1.0
        self.update(self.total, status)
