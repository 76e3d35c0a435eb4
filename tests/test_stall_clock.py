"""The stall measure: time without a heartbeat counts where the engine is stopped, blocked or hung
on a CPU, never where it is runnable but held off the CPU by a loaded machine."""

import os
import signal
import subprocess
import sys
import time

import pytest

from hil_server.service.stall_clock import ProcessProbe, StallClock


class ScriptedProbe:
    """A process whose state and CPU time the test sets."""

    def __init__(self, pid):
        self.pid = pid
        self.cpu, self.st = 0.0, "R"

    def cpu_s(self):
        return self.cpu

    def state(self):
        return self.st


def clock_with(probe):
    return StallClock(0.005, probe_for=lambda pid: probe)


def polls(clock, probe, beat, t0, n, dt=0.005, cpu_per_poll=0.0, state="R", wake=None):
    out = 0.0
    probe.st = state
    for k in range(1, n + 1):
        probe.cpu += cpu_per_poll
        out = clock.no_progress_s(beat, t0 + k * dt, 1, wake)
    return out


def test_a_stopped_or_blocked_engine_counts_wall_time():
    for state in ("T", "S", "D"):
        probe = ScriptedProbe(1)
        c = clock_with(probe)
        assert c.no_progress_s(7, 0.0, 1) == 0.0
        assert polls(c, probe, 7, 0.0, 40, state=state) == pytest.approx(0.2)


def test_a_runnable_engine_held_off_the_cpu_is_not_blamed():
    probe = ScriptedProbe(1)
    c = clock_with(probe)
    c.no_progress_s(7, 0.0, 1)
    assert polls(c, probe, 7, 0.0, 200) == 0.0                      # 1 s runnable, no CPU: no stall
    assert polls(c, probe, 7, 1.0, 40, state="T") == pytest.approx(0.2)   # then stopped: counts


def test_a_runnable_engine_hung_on_a_cpu_counts_the_cpu_it_got():
    probe = ScriptedProbe(1)
    c = clock_with(probe)
    c.no_progress_s(7, 0.0, 1)
    assert polls(c, probe, 7, 0.0, 40, cpu_per_poll=0.005) == pytest.approx(0.2)      # all of it
    c.no_progress_s(8, 0.3, 1)
    assert polls(c, probe, 8, 0.3, 40, cpu_per_poll=0.0025) == pytest.approx(0.1)     # half a CPU: half


def test_an_engine_asleep_in_its_own_timed_wait_counts_only_until_it_asked_to_wake():
    probe = ScriptedProbe(1)
    c = clock_with(probe)
    c.no_progress_s(7, 0.0, 1, 0.01)
    assert polls(c, probe, 7, 0.0, 40, state="S", wake=0.01) == pytest.approx(0.01)   # woken 190 ms late
    c.no_progress_s(8, 1.0, 1)
    assert polls(c, probe, 8, 1.0, 40, state="S") == pytest.approx(0.2)    # asleep where it said no wait


def test_a_span_the_watcher_itself_did_not_see_counts_as_one_poll():
    probe = ScriptedProbe(1)
    c = clock_with(probe)
    c.no_progress_s(7, 0.0, 1)
    assert polls(c, probe, 7, 0.0, 1, dt=0.5, state="T") == pytest.approx(0.005)     # held off 500 ms
    assert polls(c, probe, 7, 0.5, 20, state="T") == pytest.approx(0.105)            # then seen: counts


def test_progress_starts_the_count_afresh_and_an_unreadable_probe_counts_wall_time():
    probe = ScriptedProbe(1)
    c = clock_with(probe)
    c.no_progress_s(7, 0.0, 1)
    polls(c, probe, 7, 0.0, 10, state="T")
    assert c.no_progress_s(8, 0.06, 1) == 0.0
    assert c.no_progress_s(8, 0.07, 1) == pytest.approx(0.01)
    probe.cpu_s = lambda: None
    c = clock_with(probe)
    c.no_progress_s(7, 0.0, 1)
    assert polls(c, probe, 7, 0.0, 40) == pytest.approx(0.2)          # no CPU clock: wall time


@pytest.mark.realtime
def test_a_real_process_held_off_the_cpu_is_told_from_a_stopped_one():
    """Real processes: a spinning child under SCHED_IDLE, pinned to one CPU with two spinning
    neighbours, gets almost no CPU while runnable; stopped, it is state T."""
    spin = [sys.executable, "-c", "while True: pass"]
    cpu = min(os.sched_getaffinity(0))
    procs = [subprocess.Popen(spin) for _ in range(3)]
    try:
        for p in procs:
            os.sched_setaffinity(p.pid, {cpu})
        os.sched_setscheduler(procs[0].pid, os.SCHED_IDLE, os.sched_param(0))
        time.sleep(0.2)
        probe = ProcessProbe(procs[0].pid)
        assert probe.state() == "R" and probe.cpu_s() is not None
        c = StallClock(0.005)
        t0 = time.monotonic()
        c.no_progress_s(1, t0, procs[0].pid)
        while time.monotonic() - t0 < 1.0:
            held = c.no_progress_s(1, time.monotonic(), procs[0].pid)
            time.sleep(0.005)
        assert held < 0.1                       # 1 s of wall time, runnable: far under a 100 ms limit
        for p in procs[1:]:                     # it must run to act on SIGSTOP
            p.kill()
        os.kill(procs[0].pid, signal.SIGSTOP)
        t_stop = time.monotonic()
        while probe.state() != "T" and time.monotonic() - t_stop < 5.0:
            time.sleep(0.01)
        assert probe.state() == "T"
        t1 = time.monotonic()
        c.no_progress_s(2, t1, procs[0].pid)
        while time.monotonic() - t1 < 0.3:
            stopped = c.no_progress_s(2, time.monotonic(), procs[0].pid)
            time.sleep(0.005)
        assert stopped > 0.25                   # stopped: every millisecond counts
    finally:
        for p in procs:
            p.kill()
            p.wait()
