"""State documents: the plant snapshot as ``/api/v1/state`` (and the WebSocket stream) present it,
and the loop statistics with lateness percentiles.

A state is only served from a running engine: while it is down the document is refused (503 with
the reason), never served stale."""

from __future__ import annotations

import time

import numpy as np

from ..engine import shared as S
from .config import ServiceError

SOURCES = {S.SRC_NONE: "none", S.SRC_REST: "rest", S.SRC_CAN: "can", S.SRC_VIEWER: "viewer"}


def lateness_summary(ring: np.ndarray, written: int) -> dict:
    """Percentiles (us) of the lateness ring (s) the loop fills; ``written`` entries so far."""
    window = ring[: min(written, ring.shape[0])]
    if not window.size:
        return {"p50": None, "p99": None, "p999": None, "max": None, "window_ticks": 0}
    p = np.percentile(window, [50, 99, 99.9]) * 1e6
    return {"p50": float(p[0]), "p99": float(p[1]), "p999": float(p[2]), "max": float(window.max() * 1e6),
            "window_ticks": int(window.size)}


class StateDocuments:
    def __init__(self, block: S.SharedBlock, mirror, faults, supervisor):
        self.block = block
        self.mirror = mirror
        self.faults = faults
        self.supervisor = supervisor
        self._pct_cache = (0.0, {})

    def snapshot(self) -> np.ndarray:
        """A consistent copy of the state area from a running engine (503 otherwise)."""
        if not self.supervisor.running:
            raise ServiceError(self.supervisor.down_message(), 503)
        try:
            return self.block.snapshot()
        except S.SnapshotError as exc:
            raise ServiceError(str(exc), 503) from None

    def actuators(self, snap: np.ndarray) -> np.ndarray:
        n = self.block.layout.n_dof
        return snap[S.S_HDR + 2 * n:].reshape(self.block.layout.n_act, S.A_N)

    def lateness_percentiles(self) -> dict:
        now = time.monotonic()
        if now - self._pct_cache[0] < 0.1:
            return self._pct_cache[1]
        res = lateness_summary(self.block.ring, int(self.block.stats[S.T_RING_N]))
        self._pct_cache = (now, res)
        return res

    def loop_stats(self) -> dict:
        st = self.block.stats
        return {
            "rate_hz": float(st[S.T_RATE]),
            "ticks": int(st[S.T_TICKS]),
            "overruns": int(st[S.T_OVERRUNS]),
            "resyncs": int(st[S.T_RESYNCS]),
            "watchdog_trips": int(st[S.T_WD_TRIPS]),
            "lateness_us": self.lateness_percentiles(),
            "realtime_priority": bool(self.block.state[S.S_RTPRIO]),
        }

    def state(self) -> dict:
        snap = self.snapshot()
        act = self.actuators(snap)
        n = self.block.layout.n_dof
        q = snap[S.S_HDR:S.S_HDR + n]
        qd = snap[S.S_HDR + n:S.S_HDR + 2 * n]
        spec = self.mirror.spec
        tree = spec.tree
        joints = {}
        for a, js in enumerate(spec.joints):
            i = tree.index(js.dof)
            sensed = js.sensed
            joints[js.name] = {
                "angle": float(act[a, S.A_ANGLE]) if sensed else float(q[i]),
                "sensor_voltage": float(act[a, S.A_SENS_V]) if sensed else None,
                "command_voltage": float(act[a, S.A_U]),
                "requested_voltage": float(act[a, S.A_U_REQ]),
                "pressure_a": float(act[a, S.A_P_A]),
                "pressure_b": float(act[a, S.A_P_B]),
                "velocity": float(qd[i]),
                "spool": float(act[a, S.A_SPOOL]),
                "sensed": sensed,
                "watchdog": bool(act[a, S.A_WATCHDOG]),
                "source": SOURCES.get(float(act[a, S.A_SOURCE]), "none"),
            }
        return {
            "robot": spec.name,
            "time": float(snap[S.S_TIME]),
            "tick": int(snap[S.S_TICK]),
            "mode": S.MODES[int(snap[S.S_MODE])],
            "estop": bool(snap[S.S_ESTOP]),
            "diverged": bool(snap[S.S_DIVERGED]),
            "supply_pressure": float(snap[S.S_P_SUPPLY]),
            "joints": joints,
            "pose": {name: float(q[i]) for i, name in enumerate(tree.dof_names)},
            "loop": self.loop_stats(),
            "faults": self.faults.listing(),
        }
