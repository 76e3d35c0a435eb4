"""Progress of a fleet: a line when a record starts, and when one finishes: records done of those to
diagnose, its result, the ones still running, and the time left (the remaining records at the pace so
far, which already counts the records running side by side)."""

from __future__ import annotations

import time


def duration(s: float) -> str:
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.1f} min"
    return f"{s / 3600:.1f} h"


class Progress:
    def __init__(self, total: int, log, clock=time.monotonic):
        self.total = total
        self.log = log
        self.clock = clock
        self.done = 0
        self.running: list[str] = []
        self.t0: float | None = None

    def started(self, name: str) -> None:
        if self.t0 is None:
            self.t0 = self.clock()
        self.running.append(name)
        self.log(f"started {name} ({len(self.running)} running, {self.done} of {self.total} done)")

    def time_left(self) -> float | None:
        if not self.done or self.t0 is None:
            return None
        return (self.clock() - self.t0) / self.done * (self.total - self.done)

    def finished(self, name: str, text: str) -> None:
        if name in self.running:
            self.running.remove(name)
        self.done += 1
        width = len(str(self.total))
        parts = [f"[{self.done:>{width}}/{self.total}] {name}: {text}"]
        if self.running:
            parts.append("running: " + ", ".join(self.running[:4]) + (f" and {len(self.running) - 4} more" if len(self.running) > 4 else ""))
        left = self.time_left()
        if self.done < self.total and left is not None:
            parts.append(f"about {duration(left)} left")
        self.log(" | ".join(parts))
