"""How long the engine loop has made no progress by its own fault: the measure the supervisor calls
a stall (and kills the engine on).

On a loaded machine (and on a virtual one whose host takes its CPUs away) the OS keeps the engine
from running for tens of milliseconds now and then, and past a 100 ms stall limit once in a
while: runnable with no CPU, or asleep in its own timed wait past the time it asked to wake at.
That is the machine's delay, not the loop's, and killing the engine would not end it. So the time
between two polls without a heartbeat counts
- in full where the engine is stopped, blocked in a call, or asleep where it did not say it waits;
- up to the wake-up time it declared (``W_WAKE`` in the shared block) where it sleeps in its own
  timed wait;
- as the CPU time it got where it is runnable (a loop hung in a computation gets CPU and is caught);
- as one poll period where the watcher itself was held off for more than ``LATE_POLLS`` periods:
  what the engine did then was not seen (a host that stops the whole machine stops both; on this
  machine the watcher once saw nothing for 106 ms while the engine was charged 47 ms of CPU).
Where the CPU clock or the process state cannot be read, wall time counts. A hung engine is
still caught once the watcher has seen it make no progress for the limit.
"""

from __future__ import annotations

import ctypes
import time


def _libc():
    try:
        return ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None


_LIBC = _libc()


class ProcessProbe:
    """The CPU time (s) and scheduler state (``R`` runnable, ``S``/``D`` blocked, ``T`` stopped, ...)
    of one process, read from its CPU clock and ``/proc/<pid>/stat``; None where unreadable."""

    def __init__(self, pid: int):
        self.pid = pid
        self._clock = None
        clk = ctypes.c_int()
        if _LIBC is not None and hasattr(_LIBC, "clock_getcpuclockid") and \
                _LIBC.clock_getcpuclockid(int(pid), ctypes.byref(clk)) == 0:
            self._clock = clk.value

    def cpu_s(self) -> float | None:
        if self._clock is None:
            return None
        try:
            return time.clock_gettime(self._clock)
        except OSError:
            return None

    def state(self) -> str | None:
        try:
            with open(f"/proc/{self.pid}/stat") as fh:
                return fh.read().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            return None


LATE_POLLS = 4     # a watcher poll this many periods late was held off itself


class StallClock:
    """Fed the heartbeat word on every watcher poll; says how long the loop has made no progress by
    its own fault (the rules above)."""

    def __init__(self, poll_s: float, probe_for=ProcessProbe):
        """``poll_s``: the watcher's poll period (s)."""
        self.poll_s = poll_s
        self._probe_for = probe_for
        self._probe = None
        self.reset()

    def reset(self) -> None:
        self._beat: int | None = None
        self._counted = 0.0
        self._last: tuple[float, float | None] | None = None   # (time, CPU time) at the previous poll

    def no_progress_s(self, beat: int, now: float, pid: int, wake: float | None = None) -> float:
        """Seconds without progress that count against the stall limit (0 when the beat moved);
        ``now``: monotonic seconds; ``wake``: when the engine's declared timed wait ends (monotonic
        s), None when it declared none."""
        if self._probe is None or self._probe.pid != pid:
            self._probe = self._probe_for(pid)
            self._last = None
        cpu = self._probe.cpu_s()
        last, self._last = self._last, (now, cpu)
        if beat != self._beat:
            self._beat, self._counted = beat, 0.0
            return 0.0
        if last is None:
            return self._counted
        dt = now - last[0]
        if dt > LATE_POLLS * self.poll_s:
            dt = self.poll_s                           # the watcher did not see this span
        else:
            state = self._probe.state()
            if state == "R" and cpu is not None and last[1] is not None:
                dt = min(dt, max(cpu - last[1], 0.0))  # runnable: only the CPU it got counts
            elif state == "S" and wake is not None:
                dt = min(dt, max(wake - last[0], 0.0))  # in its own timed wait: only until it asked to wake
        self._counted += dt
        return self._counted
