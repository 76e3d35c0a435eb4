"""The fixed-rate plant loop (runs inside the engine process).

Realtime mode uses absolute deadlines ``t0 + k dt``: sleep until ~200 us before the deadline, then
spin (research note: p99 lateness 5-65 us in an isolated loop). A tick that starts a whole period
or more late is an overrun; missed ticks are integrated back-to-back (never skipped silently) and
only a stall of more than a second resynchronises the clock (counted). Lateness of every tick goes
into a histogram and a ring the service computes percentiles from.

Modes: ``realtime``; ``paused`` (no ticks); ``lockstep`` (exactly N ticks per ``step`` request, for
deterministic controller tests); ``fast`` (ticks back to back).
"""

from __future__ import annotations

import time

import numpy as np

from sim_core.simulator import SimulationError

from . import shared as S
from .tick_io import apply_commands, publish, record_row

SPIN_S = 200e-6
RESYNC_S = 1.0


class EngineLoop:
    def __init__(self, ctx, sim, block: S.SharedBlock, conn, *, dt: float, mode: str, watchdog_s: float,
                 realtime_priority: bool, lateness_ring: np.ndarray):
        self.ctx = ctx
        self.sim = sim
        self.block = block
        self.conn = conn
        self.dt = dt
        self.mode = mode
        self.watchdog_s = watchdog_s
        self.stop = False
        self.ring = lateness_ring
        self.ring_i = 0
        na = len(ctx.spec.joints)
        self._cmd = np.zeros((na, S.C_N))
        self._u = np.zeros(na)
        self._wd = np.zeros(na)
        self._sensed = np.array([j.sensed for j in ctx.spec.joints])
        self._sensed_idx = np.flatnonzero(self._sensed).astype(np.int64)
        self._n_dof = ctx.XQ.shape[1]
        self.tick_count = 0
        self._thresholds = np.array(S.LATENESS_BUCKETS_US) * 1e-6
        self._work = np.zeros(4096)
        self._work_i = 0
        self.recording = False
        self.block.state[S.S_RTPRIO] = 1.0 if realtime_priority else 0.0
        self.block.state[S.S_MODE] = S.MODES.index(mode)
        self.block.stats[S.T_RATE] = 1.0 / dt
        self.handlers = None  # set by the process (control message handlers)
        self._ctl_seen = 0.0
        self._publish()

    # ---- one tick -------------------------------------------------------------------------------
    def _read_commands(self) -> None:
        b = self.block
        S.SharedBlock.read(b.cmd_seq, b.cmd, self._cmd)   # a writer stuck mid-update: keep last commands
        trips = apply_commands(self._cmd, self._u, self._wd, float(b.estop[0]), self.mode == "realtime",
                               time.monotonic(), self.ctx.time, self.watchdog_s)
        if trips:
            b.stats[S.T_WD_TRIPS] += trips

    def tick(self) -> None:
        self._read_commands()
        try:
            self.sim.step(self._u, self.dt)
        except SimulationError:
            pass  # the simulator rolled the state back; hold it (never NaN in the state)
        self.tick_count += 1
        self._publish()
        if self.recording:
            self._record()

    def _publish(self) -> None:
        ctx = self.ctx
        publish(self.block.state, self._n_dof, ctx.XQ, ctx.XS, ctx.XG, self._cmd, self._u, self._wd,
                float(self.tick_count), time.time(), float(S.MODES.index(self.mode)), float(self.block.estop[0]))

    def _record(self) -> None:
        b = self.block
        rows = int(b.rec_hdr[S.R_ROWS])
        record_row(b.rec[rows % b.rec.shape[0]], self.ctx.XS, self.ctx.XG, self._u, self._sensed_idx,
                   float(self.tick_count))
        b.rec_hdr[S.R_ROWS] = rows + 1

    # ---- statistics ---------------------------------------------------------------------------
    def _account(self, lateness: float, work: float) -> None:
        st = self.block.stats
        st[S.T_TICKS] += 1.0
        if lateness >= self.dt:
            st[S.T_OVERRUNS] += 1.0
        self.ring[self.ring_i % self.ring.shape[0]] = lateness
        self.ring_i += 1
        st[-1] = self.ring_i
        k = 0
        th = self._thresholds
        while k < th.shape[0] and lateness > th[k]:
            k += 1
        self.block.buckets[k] += 1.0
        self._work[self._work_i % self._work.shape[0]] = work
        self._work_i += 1

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
                self._poll(0.05)

    def _run_realtime(self) -> None:
        dt = self.dt
        clock = time.perf_counter
        deadline = clock() + dt
        while self.mode == "realtime" and not self.stop:
            rem = deadline - clock()
            if rem > SPIN_S:
                time.sleep(rem - SPIN_S)
            while clock() < deadline:
                pass
            start = clock()
            lateness = start - deadline
            self.tick()
            work = clock() - start
            self._account(lateness, work)
            deadline += dt
            if clock() - deadline > RESYNC_S:
                self.block.stats[S.T_RESYNCS] += 1.0
                deadline = clock() + dt
            if self.block.ctl[0] != self._ctl_seen:   # a request is waiting: no syscall per tick
                self._ctl_seen = self.block.ctl[0]
                while self.conn.poll():
                    self._poll(0.0)

    def _poll(self, timeout: float) -> None:
        if self.conn.poll(timeout):
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
