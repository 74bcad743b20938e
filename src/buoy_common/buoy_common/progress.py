"""A progress bar for long offline work, on stderr, that also reads well in a CI log."""

from __future__ import annotations

import sys
import time


class Progress:
    """Reports ``done / total`` of a task: a live bar on a terminal, a line per 10 % otherwise."""

    def __init__(self, total: float, label: str, unit: str = "s", stream=None):
        self.total = max(float(total), 1e-9)
        self.label = label
        self.unit = unit
        self.stream = stream or sys.stderr
        self.interactive = self.stream.isatty()
        self.started = time.monotonic()
        self._last_draw = 0.0
        self._last_decile = -1

    def update(self, done: float) -> None:
        fraction = min(max(done / self.total, 0.0), 1.0)
        now = time.monotonic()
        if self.interactive:
            if now - self._last_draw < 0.1 and fraction < 1.0:
                return
            self._last_draw = now
            filled = int(fraction * 30)
            bar = "#" * filled + "-" * (30 - filled)
            self.stream.write(f"\r{self.label} [{bar}] {fraction:6.1%} {self._rate(done, now)}")
            self.stream.flush()
        else:
            decile = int(fraction * 10)
            if decile > self._last_decile:
                self._last_decile = decile
                self.stream.write(f"{self.label}: {fraction:.0%} {self._rate(done, now)}\n")
                self.stream.flush()

    def _rate(self, done: float, now: float) -> str:
        elapsed = now - self.started
        if elapsed <= 0 or done <= 0:
            return ""
        return f"({done / elapsed:.1f} {self.unit}/s)"

    def close(self) -> None:
        self.update(self.total)
        if self.interactive:
            self.stream.write("\n")
            self.stream.flush()
