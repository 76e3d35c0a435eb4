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

from sim_core.kernel import layout as KL
from sim_core.simulator import SimulationError

from . import shared as S

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
        self._sensed_idx = np.flatnonzero(self._sensed)
        self.tick_count = 0
        self._thresholds = np.array(S.LATENESS_BUCKETS_US) * 1e-6
        self._work = np.zeros(4096)
        self._work_i = 0
        self.recording = False
        self.block.state[S.S_RTPRIO] = 1.0 if realtime_priority else 0.0
        self.block.state[S.S_MODE] = S.MODES.index(mode)
        self.block.stats[S.T_RATE] = 1.0 / dt
        self.handlers = None  # set by the process (control message handlers)
        self._publish()

    # ---- one tick -------------------------------------------------------------------------------
    def _read_commands(self) -> None:
        b = self.block
        if not S.SharedBlock.read(b.cmd_seq, b.cmd, self._cmd):
            pass  # a writer is stuck mid-update: keep last commands
        np.copyto(self._u, self._cmd[:, S.C_VOLT])
        can = self._cmd[:, S.C_SOURCE] == S.SRC_CAN
        if self.watchdog_s > 0.0 and can.any():
            if self.mode == "realtime":
                age = time.monotonic() - self._cmd[:, S.C_T_WALL]
            else:
                age = self.ctx.time - self._cmd[:, S.C_T_SIM]
            tripped = can & (age > self.watchdog_s)
            new_trips = int(np.count_nonzero(tripped & (self._wd == 0.0)))
            if new_trips:
                b.stats[S.T_WD_TRIPS] += new_trips
            self._wd[:] = tripped
            self._u[tripped] = 0.0
        else:
            self._wd[:] = 0.0
        if b.estop[0] != 0.0:
            self._u[:] = 0.0

    def tick(self) -> None:
        self._read_commands()
        try:
            row = self.sim.step(self._u, self.dt)
        except SimulationError:
            # the state is rolled back by the simulator; hold it and report (never NaN in the state)
            row = None
        self.tick_count += 1
        self._publish(row)
        if self.recording:
            self._record(row)

    def _publish(self, row=None) -> None:
        b = self.block
        ctx = self.ctx
        st = b.state
        st[S.S_SEQ] += 1.0
        st[S.S_TICK] = self.tick_count
        st[S.S_TIME] = ctx.time
        st[S.S_WALL] = time.time()
        st[S.S_MODE] = S.MODES.index(self.mode)
        st[S.S_ESTOP] = b.estop[0]
        st[S.S_P_SUPPLY] = ctx.XG[KL.XG_P_S]
        st[S.S_ALIVE] = 1.0
        np.copyto(b.q, ctx.XQ[0])
        np.copyto(b.qd, ctx.XQ[1])
        act = b.act
        act[:, S.A_U_REQ] = self._cmd[:, S.C_VOLT]
        act[:, S.A_U] = self._u
        act[:, S.A_SOURCE] = self._cmd[:, S.C_SOURCE]
        act[:, S.A_WATCHDOG] = self._wd
        XS = ctx.XS
        act[:, S.A_SENS_V] = XS[:, KL.XS_SENS_V]
        act[:, S.A_ANGLE] = XS[:, KL.XS_SENS_ANGLE]
        act[:, S.A_P_A] = XS[:, KL.XS_P_A]
        act[:, S.A_P_B] = XS[:, KL.XS_P_B]
        act[:, S.A_SPOOL] = XS[:, KL.XS_SPOOL_X]
        st[S.S_SEQ] += 1.0

    def _record(self, row) -> None:
        b = self.block
        rows = int(b.rec_hdr[S.R_ROWS])
        cap = b.rec.shape[0]
        r = b.rec[rows % cap]
        na = self._u.shape[0]
        ns = self._sensed_idx.shape[0]
        XS = self.ctx.XS
        r[0] = self.ctx.time
        r[1:1 + na] = self._u
        r[1 + na:1 + na + ns] = XS[self._sensed_idx, KL.XS_SENS_ANGLE]
        r[1 + na + ns:1 + 2 * na + ns] = XS[:, KL.XS_P_A]
        r[1 + 2 * na + ns:1 + 3 * na + ns] = XS[:, KL.XS_P_B]
        r[-1] = self.tick_count
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
            if self.conn.poll():
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
