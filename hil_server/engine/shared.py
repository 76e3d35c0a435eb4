"""Shared memory between the service process and the engine process.

One block: a few int64 synchronisation words, then float64 areas: the command table (written by
the service: REST, CAN, viewer; read by the engine every tick), the E-STOP flag, the state snapshot
and loop statistics (written by the engine every tick), a ring of tick lateness and a ring of
recording rows.

The command table and the state snapshot are guarded by seqlocks with real acquire/release
ordering (:mod:`.atomics`), so a reader never uses a torn copy on ARM either; a read that keeps
racing the writer fails loudly (counted, shown in ``/metrics``) instead of returning a mix. The
recording ring publishes its row count with a release store after the row is written. Statistics
are single float64 values (each one written and read atomically on 64-bit hosts).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from multiprocessing import shared_memory

import numpy as np

from . import atomics as A

# synchronisation words (int64)
# W_WAKE: the CLOCK_MONOTONIC ns at which the loop's own timed wait ends, 0 outside one (the
# supervisor does not blame the loop for a wake-up the OS delivers late)
W_CMD_SEQ, W_STATE_SEQ, W_REC_ROWS, W_CTL, W_BEAT, W_WAKE, W_N = range(7)
SYNC_WORDS = 8   # padded to one cache line

# command columns
C_VOLT, C_SOURCE, C_T_WALL, C_T_SIM, C_N = 0, 1, 2, 3, 4
SRC_NONE, SRC_REST, SRC_CAN, SRC_VIEWER = 0.0, 1.0, 2.0, 3.0

# state header
S_TICK, S_TIME, S_WALL, S_MODE, S_ESTOP, S_RTPRIO, S_P_SUPPLY, S_ALIVE, S_DIVERGED, S_HDR = range(10)
# per-actuator state columns
A_U_REQ, A_U, A_SENS_V, A_ANGLE, A_P_A, A_P_B, A_SPOOL, A_WATCHDOG, A_SOURCE, A_WD_TRIPS, A_N = range(11)
# loop statistics
(T_TICKS, T_OVERRUNS, T_RESYNCS, T_RATE, T_WD_TRIPS, T_ROLLBACKS, T_DIVERGED, T_CMD_READ_FAILS, T_RING_N,
 T_N) = range(10)
LATENESS_BUCKETS_US = (10, 25, 50, 100, 250, 500, 1000, 2500, 5000, 10000, 50000)

MODES = ("realtime", "paused", "lockstep", "fast")
LATENESS_RING = 10000  # lateness (s) of the last ticks; stats[T_RING_N] counts entries written
READ_TRIES = 1000      # seqlock attempts per spin (a few microseconds)
READ_PATIENCE_S = 0.02 # a read that found no consistent copy for this long fails (counted, never used)


class SnapshotError(RuntimeError):
    """No consistent copy could be read (a writer stuck mid-update, e.g. killed while writing)."""


@dataclass(frozen=True)
class Layout:
    n_dof: int
    n_act: int
    n_sensed: int
    rec_capacity: int

    @property
    def rec_cols(self) -> int:
        # time, u per joint, measured angle per sensed joint, p_a and p_b per joint, tick
        return 1 + self.n_act + self.n_sensed + 2 * self.n_act + 1

    @property
    def state_size(self) -> int:
        return S_HDR + 2 * self.n_dof + self.n_act * A_N

    def sizes(self) -> dict[str, int]:
        return {
            "cmd": self.n_act * C_N,
            "estop": 1,
            "state": self.state_size,
            "stats": T_N + len(LATENESS_BUCKETS_US) + 1,
            "ring": LATENESS_RING,
            "rec": self.rec_capacity * self.rec_cols,
        }

    @property
    def nbytes(self) -> int:
        return 8 * (SYNC_WORDS + sum(self.sizes().values()))


class SharedBlock:
    """Numpy views onto one shared-memory block; create in the service, attach in the engine."""

    def __init__(self, layout: Layout, name: str | None = None):
        self.layout = layout
        self._shm = shared_memory.SharedMemory(name=name, create=name is None, size=layout.nbytes)
        self.owner = name is None
        self.sync = np.ndarray((SYNC_WORDS,), dtype=np.int64, buffer=self._shm.buf)
        n_float = layout.nbytes // 8 - SYNC_WORDS
        buf = np.ndarray((n_float,), dtype=np.float64, buffer=self._shm.buf, offset=8 * SYNC_WORDS)
        if self.owner:
            self.sync[:] = 0
            buf[:] = 0.0
        off = 0
        views = {}
        for key, size in layout.sizes().items():
            views[key] = buf[off:off + size]
            off += size
        self.cmd_flat = views["cmd"]
        self.cmd = self.cmd_flat.reshape(layout.n_act, C_N)
        self.estop = views["estop"]
        self.state = views["state"]
        self.stats = views["stats"]
        self.ring = views["ring"]
        self.rec = views["rec"].reshape(layout.rec_capacity, layout.rec_cols)
        n, na = layout.n_dof, layout.n_act
        self.q = self.state[S_HDR:S_HDR + n]
        self.qd = self.state[S_HDR + n:S_HDR + 2 * n]
        self.act = self.state[S_HDR + 2 * n:].reshape(na, A_N)
        self.buckets = self.stats[T_N:T_N + len(LATENESS_BUCKETS_US) + 1]
        self._buf = buf
        self.read_failures = {"state": 0, "commands": 0}   # this process's failed reads (metrics)
        self._fail_lock = threading.Lock()

    @property
    def name(self) -> str:
        return self._shm.name

    # ---- seqlocked areas ---------------------------------------------------------------------------
    def _read(self, word: int, area: np.ndarray, out: np.ndarray, what: str) -> np.ndarray:
        """Spin a little, then yield the CPU (a writer descheduled mid-update needs it), for at most
        ``READ_PATIENCE_S``; a writer that stays mid-update that long has stopped there."""
        deadline = 0.0
        while True:
            if A.read_consistent(self.sync, word, area, out, READ_TRIES):
                return out
            now = time.monotonic()
            if not deadline:
                deadline = now + READ_PATIENCE_S
            elif now > deadline:
                break
            time.sleep(0)
        with self._fail_lock:
            self.read_failures[what] += 1
        raise SnapshotError(f"no consistent copy of the {what} area within {READ_PATIENCE_S * 1e3:g} ms "
                            "(the writer stopped in the middle of an update)")

    def snapshot(self, out: np.ndarray | None = None) -> np.ndarray:
        """A consistent copy of the state area (raises :class:`SnapshotError`, counted)."""
        return self._read(W_STATE_SEQ, self.state, np.empty_like(self.state) if out is None else out, "state")

    def commands(self) -> np.ndarray:
        """A consistent copy of the command table [n_act, C_N]."""
        out = np.empty_like(self.cmd_flat)
        return self._read(W_CMD_SEQ, self.cmd_flat, out, "commands").reshape(self.layout.n_act, C_N)

    def write_commands(self, index: np.ndarray, values: np.ndarray) -> None:
        """Rows ``index`` of the command table := ``values`` [k, C_N] under the seqlock. One writer at
        a time: the service serialises its writers with a lock."""
        A.write_begin(self.sync, W_CMD_SEQ)
        self.cmd[index] = values
        A.write_end(self.sync, W_CMD_SEQ)

    def rec_rows(self) -> int:
        """Recording rows the engine has published (acquire: the rows below it are complete)."""
        return int(A.load_acquire(self.sync, W_REC_ROWS))

    def beat(self) -> int:
        return int(A.load_relaxed(self.sync, W_BEAT))

    def mode(self) -> str:
        """The engine's current mode name (one of ``MODES``)."""
        return MODES[int(self.state[S_MODE])]

    def wake_s(self) -> float | None:
        """Monotonic seconds at which the loop's current timed wait ends; None outside one."""
        ns = int(A.load_relaxed(self.sync, W_WAKE))
        return ns * 1e-9 if ns else None

    def prefault(self) -> None:
        """Touch every page of the block (read), so that none faults in later."""
        float(self._buf[::512].sum())

    def reset_for_engine(self) -> None:
        """Before a (re)started engine attaches: no writer is mid-update, nothing is alive yet."""
        for w in (W_STATE_SEQ, W_REC_ROWS, W_CTL, W_BEAT, W_WAKE):
            A.store_release(self.sync, w, 0)
        self.state[S_ALIVE] = 0.0
        self.state[S_DIVERGED] = 0.0

    def close(self) -> None:
        # drop numpy views before closing the mapping
        for attr in ("sync", "cmd_flat", "cmd", "estop", "state", "stats", "ring", "rec", "q", "qd", "act",
                     "buckets", "_buf"):
            setattr(self, attr, None)
        self._shm.close()
        if self.owner:
            try:
                self._shm.unlink()
            except FileNotFoundError:
                pass
