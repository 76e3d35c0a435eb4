"""Shared memory between the service process and the engine process.

Layout (all float64, one block): a command area written by the service (REST, CAN, viewer) and
read every tick by the engine; a state snapshot and loop statistics written by the engine every
tick; a ring of recording rows. Each area that has several writers or readers is guarded by a
sequence lock (seqlock: the writer makes the counter odd, writes, makes it even; a reader retries
until it reads the same even counter before and after). On x86 (TSO) plain stores keep their order,
which is all a seqlock needs.
"""

from __future__ import annotations

from dataclasses import dataclass
from multiprocessing import shared_memory

import numpy as np

# command columns
C_VOLT, C_SOURCE, C_T_WALL, C_T_SIM, C_N = 0, 1, 2, 3, 4
SRC_NONE, SRC_REST, SRC_CAN, SRC_VIEWER = 0.0, 1.0, 2.0, 3.0

# state header
S_SEQ, S_TICK, S_TIME, S_WALL, S_MODE, S_ESTOP, S_RTPRIO, S_P_SUPPLY, S_ALIVE, S_HDR = range(10)
# per-actuator state columns
A_U_REQ, A_U, A_SENS_V, A_ANGLE, A_P_A, A_P_B, A_SPOOL, A_WATCHDOG, A_SOURCE, A_N = range(10)
# loop statistics
T_TICKS, T_OVERRUNS, T_RESYNCS, T_LATE_P50, T_LATE_P99, T_LATE_MAX, T_WORK_P50, T_WORK_P99, T_RATE, T_WD_TRIPS, T_N = range(11)
LATENESS_BUCKETS_US = (10, 25, 50, 100, 250, 500, 1000, 2500, 5000, 10000, 50000)
# recording header: [rows written, active, stop_at_row]
R_ROWS, R_ACTIVE, R_HDR = 0, 1, 2

MODES = ("realtime", "paused", "lockstep", "fast")
LATENESS_RING = 10000  # last ticks' lateness (s); stats[-1] counts entries written


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

    def sizes(self) -> dict[str, int]:
        return {
            "cmd_seq": 1,
            "cmd": self.n_act * C_N,
            "estop": 1,
            "ctl": 1,
            "state": S_HDR + 2 * self.n_dof + self.n_act * A_N,
            "stats": T_N + len(LATENESS_BUCKETS_US) + 1 + 1,
            "ring": LATENESS_RING,
            "rec_hdr": R_HDR + 1,
            "rec": self.rec_capacity * self.rec_cols,
        }

    @property
    def nbytes(self) -> int:
        return 8 * sum(self.sizes().values())


class SharedBlock:
    """Numpy views onto one shared-memory block; create in the service, attach in the engine."""

    def __init__(self, layout: Layout, name: str | None = None):
        self.layout = layout
        self._shm = shared_memory.SharedMemory(name=name, create=name is None, size=layout.nbytes)
        self.owner = name is None
        buf = np.ndarray((layout.nbytes // 8,), dtype=np.float64, buffer=self._shm.buf)
        if self.owner:
            buf[:] = 0.0
        off = 0
        views = {}
        for key, size in layout.sizes().items():
            views[key] = buf[off:off + size]
            off += size
        self.cmd_seq = views["cmd_seq"]
        self.cmd = views["cmd"].reshape(layout.n_act, C_N)
        self.estop = views["estop"]
        self.ctl = views["ctl"]      # bumped by the service before each control request
        self.state = views["state"]
        self.stats = views["stats"]
        self.ring = views["ring"]
        self.rec_hdr = views["rec_hdr"]
        self.rec = views["rec"].reshape(layout.rec_capacity, layout.rec_cols)
        n, na = layout.n_dof, layout.n_act
        self.q = self.state[S_HDR:S_HDR + n]
        self.qd = self.state[S_HDR + n:S_HDR + 2 * n]
        self.act = self.state[S_HDR + 2 * n:].reshape(na, A_N)
        self.buckets = self.stats[T_N:T_N + len(LATENESS_BUCKETS_US) + 1]
        self._buf = buf

    @property
    def name(self) -> str:
        return self._shm.name

    # ---- seqlock helpers -----------------------------------------------------------------------
    @staticmethod
    def write_begin(seq: np.ndarray) -> None:
        seq[0] += 1.0  # odd: writing

    @staticmethod
    def write_end(seq: np.ndarray) -> None:
        seq[0] += 1.0  # even: consistent

    @staticmethod
    def read(seq: np.ndarray, area: np.ndarray, out: np.ndarray, tries: int = 1000) -> bool:
        for _ in range(tries):
            s0 = seq[0]
            if s0 % 2.0 == 0.0:
                np.copyto(out, area)
                if seq[0] == s0:
                    return True
        return False

    def snapshot(self) -> np.ndarray:
        """A consistent copy of the state area (state[S_SEQ] is its own seqlock)."""
        out = np.empty_like(self.state)
        seq = self.state[S_SEQ:S_SEQ + 1]
        for _ in range(10000):
            s0 = seq[0]
            if s0 % 2.0 == 0.0:
                np.copyto(out, self.state)
                if seq[0] == s0:
                    return out
        np.copyto(out, self.state)
        return out

    def close(self) -> None:
        # drop numpy views before closing the mapping
        for attr in ("cmd_seq", "cmd", "estop", "ctl", "state", "stats", "ring", "rec_hdr", "rec", "q", "qd", "act", "buckets", "_buf"):
            setattr(self, attr, None)
        self._shm.close()
        if self.owner:
            try:
                self._shm.unlink()
            except FileNotFoundError:
                pass
