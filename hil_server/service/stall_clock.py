"""How long the engine loop has made no progress by its own fault: the measure the supervisor calls
a stall (and kills the engine on).

Outside ``realtime`` mode the loop runs at normal priority by design (a long lockstep step or a
``fast`` run must not starve the host), and on a loaded machine the OS keeps it waiting for a CPU
for tens of milliseconds, now and then for more than the stall limit. That wait is the machine's,
not the loop's, and killing the engine would not end it. So the time between two polls without a
heartbeat counts in full where the engine is not runnable (stopped, or blocked in a call), and
only as the CPU time it got where it is runnable (a loop hung in a computation gets CPU and is
caught; a loop held off the CPU is not blamed). Where the CPU clock or the process state cannot be
read, wall time counts.
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


class StallClock:
    """Fed the heartbeat word on every watcher poll; says how long the loop has made no progress,
    counting a runnable engine's wait for a CPU out."""

    def __init__(self, probe_for=ProcessProbe):
        self._probe_for = probe_for
        self._probe = None
        self.reset()

    def reset(self) -> None:
        self._beat: int | None = None
        self._counted = 0.0
        self._last: tuple[float, float | None] | None = None   # (time, CPU time) at the previous poll

    def no_progress_s(self, beat: int, now: float, pid: int) -> float:
        """Seconds without progress that count against the stall limit (0 when the beat moved);
        ``now``: monotonic seconds."""
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
        if cpu is not None and last[1] is not None and self._probe.state() == "R":
            dt = min(dt, max(cpu - last[1], 0.0))      # runnable: only the CPU it got counts
        self._counted += dt
        return self._counted
