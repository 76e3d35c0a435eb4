"""The plant over CAN: python-can's stock socketcand client and the emulator's shipped DBC.

This is all a controller needs to drive ``hydrohil serve --can socketcand:PORT`` exactly as it
would drive the real machine's valve electronics: it sends ``ValveCommand_<joint>`` frames and
reads ``JointFeedback_<joint>`` / ``JointPressure_<joint>`` bursts, decoded with cantools.

Modes:

* ``lockstep``: per control period send this period's commands, then ``ticks`` SYNC frames; the
  emulator advances one tick per SYNC and answers each with a feedback burst (frames on one TCP
  connection stay in order). Deterministic: the same controller gives the same trace every run.
  Time is ``ticks * tick_s`` since the first SYNC after a reset.
* ``realtime``: the emulator runs on its own clock and sends feedback cyclically (``--feedback-rate``);
  the controller sends its commands and waits for the next burst, so it runs at the feedback rate.
  If it falls behind, older bursts are dropped and the newest one is used. Time is wall time since
  :meth:`CanPlant.start`. The command watchdog neutralises a joint whose commands stop.
"""

from __future__ import annotations

import time
from pathlib import Path

import can
import cantools
import numpy as np

from .plant import STATUS_NOT_SENSED, Observation, PlantClient


class CanPlantError(RuntimeError):
    """The emulator did not answer as the protocol says (no feedback in time, bad DBC)."""


def default_dbc(robot: str) -> Path:
    """The DBC ``hydrohil serve`` ships for ``robot`` (same file ``hydrohil dbc --robot R`` prints)."""
    from hil_server.can.dbc import dbc_path

    return dbc_path(robot)


class CanPlant(PlantClient):
    """Plant client over socketcand.

    ``joints``: actuated joints in the DBC's order (``ValveCommand_<j>``); taken from the DBC when
    omitted. ``tick_s``: the emulator's tick (s, ``1/--rate``); ``ticks``: emulator ticks per control
    period in lockstep mode (the control period is ``ticks * tick_s``).
    """

    def __init__(self, port: int, robot: str, *, host: str = "127.0.0.1", mode: str = "lockstep",
                 dbc: str | Path | None = None, tick_s: float = 1e-3, ticks: int = 1,
                 feedback_rate_hz: float | None = None, timeout_s: float = 5.0):
        if mode not in ("lockstep", "realtime"):
            raise ValueError(f"mode {mode!r}: lockstep or realtime")
        if ticks < 1:
            raise ValueError("ticks per control period must be >= 1")
        self.mode = mode
        self.tick_s = float(tick_s)
        self.ticks = int(ticks)
        self.dt = self.tick_s * self.ticks if mode == "lockstep" else 1.0 / float(feedback_rate_hz or 1.0 / (tick_s * ticks))
        self.timeout_s = timeout_s
        self.db = cantools.database.load_file(str(dbc or default_dbc(robot)))
        names = [m.name for m in self.db.messages]
        self.joints = [n[len("ValveCommand_"):] for n in names if n.startswith("ValveCommand_")]
        self.joints.sort(key=lambda j: self.db.get_message_by_name(f"ValveCommand_{j}").frame_id)
        if not self.joints:
            raise CanPlantError("the DBC has no ValveCommand_<joint> messages")
        na = len(self.joints)
        self._cmd = [self.db.get_message_by_name(f"ValveCommand_{j}") for j in self.joints]
        self._range = [(m.get_signal_by_name("voltage").minimum, m.get_signal_by_name("voltage").maximum) for m in self._cmd]
        self._sync = self.db.get_message_by_name("Sync")
        self._rx: dict[int, tuple[str, int, object]] = {}
        for a, j in enumerate(self.joints):
            fb = self.db.get_message_by_name(f"JointFeedback_{j}")
            pr = self.db.get_message_by_name(f"JointPressure_{j}")
            self._rx[fb.frame_id] = ("fb", a, fb)
            self._rx[pr.frame_id] = ("pr", a, pr)
        self._na = na
        self._counter = 0
        self._sync_counter = 0
        self._ticks_done = 0
        self._t0 = None
        self._pending: dict[int, dict] = {}
        self.emergencies: list[dict] = []
        emcy = [m for m in self.db.messages if m.name == "Emergency"]
        self._emcy = emcy[0] if emcy else None
        self.bus = can.Bus(interface="socketcand", host=host, port=int(port), channel="vcan0", tcp_tune=True)

    # ---- frames ---------------------------------------------------------------------------------
    def _send(self, message, values) -> None:
        self.bus.send(can.Message(arbitration_id=message.frame_id, data=message.encode(values), is_extended_id=False))

    def _send_commands(self, u) -> None:
        u = np.asarray(u, dtype=float)
        if u.shape != (self._na,):
            raise ValueError(f"command must have {self._na} voltages ({', '.join(self.joints)}), got shape {u.shape}")
        self._counter = (self._counter + 1) & 0xFF
        for a, m in enumerate(self._cmd):
            lo, hi = self._range[a]
            v = float(np.clip(u[a], lo, hi)) if np.isfinite(u[a]) else 0.0
            self._send(m, {"voltage": v, "counter": self._counter})

    def _sync_once(self) -> None:
        self._sync_counter = (self._sync_counter + 1) & 0xFF
        self._send(self._sync, {"counter": self._sync_counter})

    def _read_burst(self, block: bool = True) -> dict | None:
        """Next complete feedback burst (all joints' JointFeedback + JointPressure with one counter)."""
        deadline = time.monotonic() + self.timeout_s
        while True:
            timeout = max(0.0, deadline - time.monotonic()) if block else 0.0
            msg = self.bus.recv(timeout)
            if msg is None:
                if not block:
                    return None
                raise CanPlantError(f"no complete feedback burst within {self.timeout_s} s (is the emulator in "
                                    f"{self.mode} mode on this port?)")
            entry = self._rx.get(msg.arbitration_id)
            if entry is None:
                if self._emcy is not None and msg.arbitration_id == self._emcy.frame_id:
                    self.emergencies.append(self._emcy.decode(bytes(msg.data), decode_choices=False))
                continue
            kind, a, m = entry
            d = m.decode(bytes(msg.data), decode_choices=False)
            c = int(d["counter"])
            burst = self._pending.get(c)
            if burst is None:
                burst = self._pending[c] = {"fb": [None] * self._na, "pr": [None] * self._na, "n": 0}
                if len(self._pending) > 4:   # stale partial bursts (realtime): keep the newest few
                    for old in list(self._pending)[:-4]:
                        del self._pending[old]
            if burst[kind][a] is None:
                burst["n"] += 1
            burst[kind][a] = d
            if burst["n"] == 2 * self._na:
                del self._pending[c]
                return burst

    def _observation(self, burst: dict, t: float) -> Observation:
        na = self._na
        angle = np.empty(na)
        vel = np.empty(na)
        pa = np.empty(na)
        pb = np.empty(na)
        ua = np.empty(na)
        sp = np.empty(na)
        st = np.zeros(na, dtype=int)
        for a in range(na):
            fb, pr = burst["fb"][a], burst["pr"][a]
            st[a] = int(fb["status"])
            angle[a] = np.nan if st[a] & STATUS_NOT_SENSED else fb["angle"]
            vel[a] = fb["velocity"]
            pa[a], pb[a] = pr["pressure_a"], pr["pressure_b"]
            ua[a], sp[a] = pr["command_voltage"], pr["spool"]
        return Observation(t, angle, vel, pa, pb, ua, sp, st)

    # ---- PlantClient ------------------------------------------------------------------------------
    def start(self) -> Observation:
        """First observation. Lockstep: one SYNC with every valve neutral (the emulator was just reset)."""
        if self.mode == "lockstep":
            self._send_commands(np.zeros(self._na))
            self._sync_once()
            burst = self._read_burst()
            self._ticks_done = 1
            return self._observation(burst, self._ticks_done * self.tick_s)
        burst = self._latest()
        self._t0 = time.monotonic()
        return self._observation(burst, 0.0)

    def _latest(self) -> dict:
        burst = self._read_burst()
        while True:   # drop anything older than the newest complete burst
            newer = self._read_burst(block=False)
            if newer is None:
                return burst
            burst = newer

    def exchange(self, u) -> Observation:
        self._send_commands(u)
        if self.mode == "lockstep":
            for _ in range(self.ticks):
                self._sync_once()
            burst = None
            for _ in range(self.ticks):
                burst = self._read_burst()
            self._ticks_done += self.ticks
            return self._observation(burst, self._ticks_done * self.tick_s)
        burst = self._latest()
        return self._observation(burst, time.monotonic() - self._t0)

    def neutral(self) -> None:
        """Send every valve neutral (0 V) once (end of a realtime run: do not wait for the watchdog)."""
        self._send_commands(np.zeros(self._na))

    def close(self) -> None:
        try:
            if self.mode == "realtime":
                self.neutral()
        except (can.CanError, OSError):
            pass
        self.bus.shutdown()
