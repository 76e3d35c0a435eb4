"""The fixed-rate plant loop (runs inside the engine process).

Realtime mode uses absolute deadlines ``t0 + k dt``: the clock waits until the deadline (the real
clock sleeps until ~200 us before it, then spins: research note, p99 lateness 5-65 us in an
isolated loop). A tick that starts a whole period or more late is an overrun; missed ticks are
integrated back-to-back (never skipped silently) and only a stall of more than a second
resynchronises the clock (counted). Lateness of every tick goes into a histogram and a ring the
service computes percentiles from. The clock is injected, so the timing rules are tested with a
scripted one.

A step the simulator rejects (non-finite state) is rolled back by the simulator. The same command
on the same state fails again, so after ``DIVERGE_AFTER`` rollbacks in a row the loop latches the
``diverged`` fault: valves neutral, the plant no longer stepped (its last finite state stays on
show), the service told with the state and the simulator's reason. ``reset`` clears it.

Modes: ``realtime``; ``paused`` (no ticks); ``lockstep`` (exactly N ticks per ``step`` request, for
deterministic controller tests); ``fast`` (ticks back to back). The loop bumps a heartbeat word
every tick and at least every ``IDLE_POLL_S`` when idle: the service's supervisor watches it.
"""

from __future__ import annotations

import time

import numpy as np

from sim_core.simulator import SimulationError

from . import atomics as A
from . import shared as S
from .tick_io import K_P_A, K_P_B, apply_commands, plant_columns, publish, record_row

SPIN_S = 200e-6
RESYNC_S = 1.0
IDLE_POLL_S = 0.01
DIVERGE_AFTER = 5          # rollbacks in a row that latch the diverged fault


class RealClock:
    """``perf_counter`` seconds; waits by sleeping until ``SPIN_S`` before the deadline, then spinning."""

    now = staticmethod(time.perf_counter)

    @staticmethod
    def wait_until(deadline: float) -> None:
        rem = deadline - time.perf_counter()
        if rem > SPIN_S:
            time.sleep(rem - SPIN_S)
        while time.perf_counter() < deadline:
            pass


class EngineLoop:
    def __init__(self, ctx, sim, block: S.SharedBlock, conn, *, dt: float, mode: str, watchdog_s: float,
                 realtime_priority: bool, events=None, clock=None):
        self.ctx = ctx
        self.sim = sim
        self.block = block
        self.conn = conn
        self.events = events          # one-way pipe to the service's supervisor (diverged, ...)
        self.clock = clock or RealClock()
        self.dt = dt
        self.mode = mode
        self.watchdog_s = watchdog_s
        self.stop = False
        na = len(ctx.spec.joints)
        self._cmd = np.zeros((na, S.C_N))
        self._cmd_flat = self._cmd.reshape(-1)
        self._u = np.zeros(na)
        self._wd = np.zeros(na)
        self._wd_trips = np.zeros(na)
        self._sensed_idx = np.flatnonzero([j.sensed for j in ctx.spec.joints]).astype(np.int64)
        self._n_dof = ctx.XQ.shape[1]
        self._cols = plant_columns()
        self.tick_count = 0
        self._thresholds = np.array(S.LATENESS_BUCKETS_US) * 1e-6
        self.recording = False
        self.diverged = False
        self.rollbacks_in_a_row = 0
        self.handlers = None  # set by the process (control message handlers)
        self._ctl_seen = 0
        st = block.stats
        block.state[S.S_RTPRIO] = 1.0 if realtime_priority else 0.0
        st[S.T_RATE] = 1.0 / dt
        self._warm_up()
        self._publish()

    def _warm_up(self) -> None:
        """Load every compiled per-tick function now: a first call in the running loop (numba loading
        or compiling it) would stall the plant for tens of milliseconds to seconds."""
        scratch_sync = np.zeros(S.SYNC_WORDS, dtype=np.int64)
        scratch_rec = np.zeros((2, self.block.rec.shape[1]))
        record_row(scratch_sync, scratch_rec, self._cols, self.ctx.XS, self.ctx.XG, self._u, self._sensed_idx, 0.0)
        A.read_consistent(scratch_sync, S.W_CMD_SEQ, self.block.cmd_flat, self._cmd_flat, 1)
        A.load_relaxed(scratch_sync, S.W_CTL)
        A.fetch_add(scratch_sync, S.W_BEAT, 1)
        A.store_release(scratch_sync, S.W_WAKE, 0)
        apply_commands(self._cmd, self._u.copy(), self._wd.copy(), self._wd_trips.copy(), 0.0, True, 0.0, 0.0,
                       self.watchdog_s)

    # ---- one tick -------------------------------------------------------------------------------
    def _read_commands(self) -> None:
        b = self.block
        if not A.read_consistent(b.sync, S.W_CMD_SEQ, b.cmd_flat, self._cmd_flat, 1000):
            b.stats[S.T_CMD_READ_FAILS] += 1.0   # a writer stuck mid-update: keep the last commands
        hold = 1.0 if (b.estop[0] != 0.0 or self.diverged) else 0.0
        trips = apply_commands(self._cmd, self._u, self._wd, self._wd_trips, hold, self.mode == "realtime",
                               time.monotonic(), self.ctx.time, self.watchdog_s)
        if trips:
            b.stats[S.T_WD_TRIPS] += trips

    def tick(self) -> None:
        self._read_commands()
        if not self.diverged:
            try:
                self.sim.step(self._u, self.dt)
                self.rollbacks_in_a_row = 0
            except SimulationError as exc:   # the simulator rolled the state back (never NaN in the state)
                self.block.stats[S.T_ROLLBACKS] += 1.0
                self.rollbacks_in_a_row += 1
                if self.rollbacks_in_a_row >= DIVERGE_AFTER:
                    self._latch_diverged(str(exc))
        self.tick_count += 1
        self._publish()
        if self.recording:
            record_row(self.block.sync, self.block.rec, self._cols, self.ctx.XS, self.ctx.XG, self._u,
                       self._sensed_idx, float(self.tick_count))
        A.fetch_add(self.block.sync, S.W_BEAT, 1)

    def _latch_diverged(self, reason: str) -> None:
        self.diverged = True
        self.block.stats[S.T_DIVERGED] += 1.0
        self._u[:] = 0.0
        ctx = self.ctx
        spec = ctx.spec
        cols = self._cols
        info = {
            "time": float(ctx.time), "tick": self.tick_count, "rollbacks": self.rollbacks_in_a_row, "reason": reason,
            "q": {d: float(v) for d, v in zip(spec.tree.dof_names, ctx.XQ[0])},
            "qd": {d: float(v) for d, v in zip(spec.tree.dof_names, ctx.XQ[1])},
            "pressure_a": {j.name: float(ctx.XS[a, cols[K_P_A]]) for a, j in enumerate(spec.joints)},
            "pressure_b": {j.name: float(ctx.XS[a, cols[K_P_B]]) for a, j in enumerate(spec.joints)},
            "command": {j.name: float(self._cmd[a, S.C_VOLT]) for a, j in enumerate(spec.joints)},
        }
        if self.events is not None:
            try:
                self.events.send(("diverged", info))
            except (OSError, ValueError):
                pass

    def clear_diverged(self) -> None:
        self.diverged = False
        self.rollbacks_in_a_row = 0

    def _publish(self) -> None:
        ctx = self.ctx
        publish(self.block.sync, self.block.state, self._cols, self._n_dof, ctx.XQ, ctx.XS, ctx.XG, self._cmd,
                self._u, self._wd, self._wd_trips, float(self.tick_count), time.time(), float(S.MODES.index(self.mode)),
                float(self.block.estop[0]), 1.0 if self.diverged else 0.0)

    # ---- statistics ---------------------------------------------------------------------------
    def _account(self, lateness: float) -> None:
        st = self.block.stats
        st[S.T_TICKS] += 1.0
        if lateness >= self.dt:
            st[S.T_OVERRUNS] += 1.0
        n = int(st[S.T_RING_N])
        self.block.ring[n % self.block.ring.shape[0]] = lateness
        st[S.T_RING_N] = n + 1
        self.block.buckets[np.searchsorted(self._thresholds, lateness)] += 1.0

    # ---- modes ---------------------------------------------------------------------------------
    def run(self) -> None:
        while not self.stop:
            if self.mode == "realtime":
                self._run_realtime()
            elif self.mode == "fast":
                self.tick()
                self.block.stats[S.T_TICKS] += 1.0
                self._poll(0.0)
            else:  # paused / lockstep: only control messages move time
                A.fetch_add(self.block.sync, S.W_BEAT, 1)
                self._poll(IDLE_POLL_S)

    def _run_realtime(self) -> None:
        dt = self.dt
        clock = self.clock
        deadline = clock.now() + dt
        while self.mode == "realtime" and not self.stop:
            self._declare_wait(deadline - clock.now())
            clock.wait_until(deadline)
            self._declare_wait(None)
            lateness = clock.now() - deadline
            self.tick()
            self._account(lateness)
            deadline += dt
            if clock.now() - deadline > RESYNC_S:   # a stall: start afresh rather than run a second of ticks flat out
                self.block.stats[S.T_RESYNCS] += 1.0
                deadline = clock.now() + dt
            ctl = A.load_relaxed(self.block.sync, S.W_CTL)
            if ctl != self._ctl_seen:   # a request is waiting: no syscall per tick otherwise
                self._ctl_seen = ctl
                while self.conn.poll():
                    self._poll(0.0)

    def _declare_wait(self, seconds: float | None) -> None:
        """Say in the shared block until when the loop waits of its own accord (None: it stopped
        waiting), so that a wake-up the OS delivers late is not taken for a stall."""
        wake = 0 if seconds is None else time.monotonic_ns() + max(int(seconds * 1e9), 0) + 1
        A.store_release(self.block.sync, S.W_WAKE, wake)

    def _poll(self, timeout: float) -> None:
        if timeout > 0.0:
            self._declare_wait(timeout)
            ready = self.conn.poll(timeout)
            self._declare_wait(None)
        else:
            ready = self.conn.poll(0.0)
        if ready:
            try:
                msg = self.conn.recv()
            except (EOFError, OSError):
                self.stop = True
                return
            self.handlers(msg)

    def run_ticks(self, n: int) -> None:
        for _ in range(n):
            self.tick()
            self.block.stats[S.T_TICKS] += 1.0
