"""CAN bridge: ValveCommand frames in, JointFeedback / JointPressure / HilStatus / Heartbeat / EMCY out.

Everything runs on one asyncio event loop (uvicorn's under ``hydrohil serve``): no CAN thread
competes with the REST server for the GIL.

Receive: a command frame with the right DLC and an in-range voltage becomes the joint's
command (source CAN, so the engine's watchdog guards it); SYNC advances the plant one tick in
lockstep mode and answers with feedback at once. Anything else (wrong DLC, unknown id, remote or
error frames, out-of-range commands, frames beyond the flood budget) is counted and ignored; the
plant runs in its own process, so a flood cannot slow its loop.

Transmit task: cyclic feedback at ``feedback_rate`` in realtime/fast modes (in lockstep and paused,
whenever a tick happened), status at 10 Hz, heartbeat at 1 Hz, and an EMCY when a watchdog trip
or a fault starts (error code) or ends (0x0000).
"""

from __future__ import annotations

import asyncio
import logging
import time

import can
import numpy as np

from ..engine import shared as S
from . import dbc as D
from .transports import open_transport

log = logging.getLogger("hydrohil.can")

FLOOD_RATE = 20000.0   # frames/s accepted from the bus before frames count as flood
NA_ANGLE = 0x7FFF
NA_VOLT = 0xFFFF


class CanBridge:
    def __init__(self, service, spec_str: str, feedback_rate: float | None = None):
        self.service = service
        self.spec_str = spec_str
        self.db = D.load_database(service.spec.name)
        joints = service.spec.joint_names
        self.joints = joints
        self.cmd_msgs = {}
        for a, j in enumerate(joints):
            m = self.db.get_message_by_name(f"ValveCommand_{j}")
            self.cmd_msgs[m.frame_id] = (a, m)
        self.fb_msgs = [self.db.get_message_by_name(f"JointFeedback_{j}") for j in joints]
        self.pr_msgs = [self.db.get_message_by_name(f"JointPressure_{j}") for j in joints]
        self.status_msg = self.db.get_message_by_name("HilStatus")
        self.emcy_msg = self.db.get_message_by_name("Emergency")
        self.hb_msg = self.db.get_message_by_name("Heartbeat")
        self.sync_id = self.db.get_message_by_name("Sync").frame_id
        self.ranges = [service.spec.joint(j).command_range for j in joints]
        self.sensed = [service.spec.joint(j).sensed for j in joints]
        self.feedback_rate = feedback_rate or service.cfg.feedback_rate_hz
        self.counters: dict[tuple[str, str], int] = {}
        self._clock = {"tokens": FLOOD_RATE, "t": time.monotonic()}
        self._fb_counter = 0
        self._last_fb_tick = -1
        self._wd_prev = np.zeros(len(joints))
        self._faults_prev: set[str] = set()
        self._occurrence: dict[tuple, int] = {}
        self.transport = None
        self._tx_task: asyncio.Task | None = None

    # ---- lifecycle (coroutines: run on the bridge's event loop) ---------------------------------
    async def start(self) -> None:
        self.transport = open_transport(self.spec_str)
        await self.transport.start(self._handle_safe)
        self._tx_task = asyncio.create_task(self._tx_loop())
        log.info("CAN on %s", self.spec_str)

    async def close(self) -> None:
        if self._tx_task is not None:
            self._tx_task.cancel()
            try:
                await self._tx_task
            except (asyncio.CancelledError, Exception):  # noqa: BLE001
                pass
        if self.transport is not None:
            await self.transport.close()

    def describe(self) -> dict:
        d = {"transport": self.spec_str, "feedback_rate_hz": self.feedback_rate,
             "frames": {f"{k[0]}.{k[1]}": v for k, v in sorted(self.counters.items())}}
        if self.transport is not None:
            d.update(self.transport.describe())
            for k, v in getattr(self.transport, "counters", {}).items():
                d["frames"][f"transport.{k}"] = v
        return d

    def count(self, direction: str, kind: str, n: int = 1) -> None:
        key = (direction, kind)
        self.counters[key] = self.counters.get(key, 0) + n

    # ---- receive -------------------------------------------------------------------------------
    def _admit(self) -> bool:
        now = time.monotonic()
        c = self._clock
        c["tokens"] = min(FLOOD_RATE, c["tokens"] + (now - c["t"]) * FLOOD_RATE)
        c["t"] = now
        if c["tokens"] < 1.0:
            return False
        c["tokens"] -= 1.0
        return True

    def _handle_safe(self, msg: can.Message) -> None:
        try:
            self.handle(msg)
        except Exception:  # noqa: BLE001 - a bad frame must never stop the bridge
            self.count("rx", "malformed")
            log.exception("frame %s", msg)

    def handle(self, msg: can.Message) -> None:
        if not self._admit():
            self.count("rx", "flood_dropped")
            return
        if msg.is_error_frame:
            self.count("rx", "error_frame")
            return
        if msg.is_remote_frame:
            self.count("rx", "remote_frame")
            return
        fid = msg.arbitration_id
        entry = self.cmd_msgs.get(fid) if not msg.is_extended_id else None
        if entry is not None:
            a, m = entry
            if msg.dlc != m.length:
                self.count("rx", "wrong_dlc")
                self._emcy(D.EMCY_LENGTH, a, D.FMI_ERRATIC)
                return
            volts = m.decode(bytes(msg.data), decode_choices=False)["voltage"]
            lo, hi = self.ranges[a]
            if not lo <= volts <= hi:
                self.count("rx", "out_of_range")
                self._emcy(D.EMCY_RANGE, a, D.FMI_ABOVE)
                return
            self.service.write_commands({a: float(volts)}, S.SRC_CAN)
            self.count("rx", "command")
            return
        if fid == self.sync_id and not msg.is_extended_id:
            if msg.dlc > 1:
                self.count("rx", "wrong_dlc")
                return
            self.count("rx", "sync")
            mode = S.MODES[int(self.service.block.state[S.S_MODE])]
            if mode == "lockstep":
                self.service.step(1)
                self.send_feedback()
            return
        self.count("rx", "unknown_id")

    # ---- transmit -----------------------------------------------------------------------------
    def _frame(self, message, values: dict) -> can.Message:
        return can.Message(arbitration_id=message.frame_id, data=message.encode(values, scaling=True, strict=False),
                           is_extended_id=False, timestamp=time.time())

    def _send(self, message, values: dict, kind: str) -> None:
        self._send_frames([self._frame(message, values)], kind)

    def _send_frames(self, frames, kind: str) -> None:
        try:
            self.transport.send_many(frames)
        except (can.CanError, OSError):
            self.count("tx", "failed")
            return
        self.count("tx", kind, len(frames))

    def send_feedback(self) -> None:
        svc = self.service
        snap = svc.block.snapshot()
        n = svc.layout.n_dof
        act = snap[S.S_HDR + 2 * n:].reshape(svc.layout.n_act, S.A_N)
        qd = snap[S.S_HDR + n:S.S_HDR + 2 * n]
        estop = snap[S.S_ESTOP] != 0.0
        faulted = {f["joint"] for f in svc.faults.values()}
        self._fb_counter = (self._fb_counter + 1) & 0xFF
        tree = svc.spec.tree
        frames = []
        for a, j in enumerate(self.joints):
            status = (D.STATUS_WATCHDOG if act[a, S.A_WATCHDOG] else 0) | (D.STATUS_FAULT if j in faulted else 0) \
                | (D.STATUS_ESTOP if estop else 0) | (0 if self.sensed[a] else D.STATUS_NOT_SENSED)
            vel = float(np.clip(qd[tree.index(svc.spec.joint(j).dof)], -32.7, 32.7))
            if self.sensed[a]:
                fb = {"angle": float(np.clip(act[a, S.A_ANGLE], -3.2767, 3.2767)),
                      "sensor_voltage": float(np.clip(act[a, S.A_SENS_V], 0.0, 13.1)),
                      "velocity": vel, "status": status, "counter": self._fb_counter}
            else:
                fb = {"angle": NA_ANGLE * 1e-4, "sensor_voltage": NA_VOLT * 2e-4, "velocity": vel,
                      "status": status, "counter": self._fb_counter}
            frames.append(self._frame(self.fb_msgs[a], fb))
            lo, hi = self.ranges[a]
            frames.append(self._frame(self.pr_msgs[a], {
                "pressure_a": float(np.clip(act[a, S.A_P_A], 0.0, 65.5e6)),
                "pressure_b": float(np.clip(act[a, S.A_P_B], 0.0, 65.5e6)),
                "command_voltage": float(np.clip(act[a, S.A_U], lo, hi)),
                "spool": float(np.clip(act[a, S.A_SPOOL], -1.28, 1.27)),
                "counter": self._fb_counter}))
        self._send_frames(frames, "feedback")
        self._last_fb_tick = int(snap[S.S_TICK])
        self._check_events(act)

    def send_status(self) -> None:
        svc = self.service
        st = svc.block.state
        act = svc.block.act
        mask = 0
        for a in range(len(self.joints)):
            if act[a, S.A_WATCHDOG]:
                mask |= 1 << a
        state = 3 if st[S.S_ESTOP] else (2 if svc.faults else (1 if mask else 0))
        self._send(self.status_msg, {"mode": int(st[S.S_MODE]), "state": state, "watchdog_mask": mask,
                                     "tick": int(st[S.S_TICK]) & 0xFFFF}, "status")

    def send_heartbeat(self) -> None:
        mode = S.MODES[int(self.service.block.state[S.S_MODE])]
        nmt = 5 if mode in ("realtime", "fast", "lockstep") else 127
        self._send(self.hb_msg, {"nmt_state": nmt}, "heartbeat")

    def _emcy(self, code: int, joint: int | None, fmi: int) -> None:
        key = (code, joint, fmi)
        occ = self._occurrence.get(key, 0) + 1 if code != D.EMCY_RESET else 1
        self._occurrence[key] = min(occ, 255)
        self._send(self.emcy_msg, {"error_code": code, "error_register": 0x11 if code else 0,
                                   "joint": 0xFF if joint is None else joint,
                                   "spn": D.SPN_BASE + (0 if joint is None else joint), "fmi": fmi,
                                   "occurrence": self._occurrence[key]}, "emcy")

    def _check_events(self, act=None) -> None:
        act = self.service.block.act if act is None else act
        wd = act[:, S.A_WATCHDOG].copy()
        for a in np.flatnonzero(wd != self._wd_prev):
            if wd[a]:
                self._emcy(D.EMCY_TIMEOUT, int(a), D.FMI_TIMEOUT)
            else:
                self._emcy(D.EMCY_RESET, int(a), D.FMI_TIMEOUT)
        self._wd_prev = wd
        faults = set(self.service.faults)
        for fid in faults - self._faults_prev:
            f = self.service.faults.get(fid)
            if f:
                j = f["joint"]
                self._emcy(D.EMCY_HARDWARE, None if j is None else self.joints.index(j), D.FMI_BAD_DEVICE)
        for fid in self._faults_prev - faults:
            kind, _, j = fid.partition(":")
            self._emcy(D.EMCY_RESET, self.joints.index(j) if j in self.joints else None, D.FMI_BAD_DEVICE)
        self._faults_prev = faults

    async def _tx_loop(self) -> None:
        period = 1.0 / self.feedback_rate
        loop = asyncio.get_running_loop()
        next_fb = next_status = next_hb = loop.time()
        while True:
            now = loop.time()
            mode = S.MODES[int(self.service.block.state[S.S_MODE])]
            try:
                if mode in ("realtime", "fast"):
                    if now >= next_fb:
                        self.send_feedback()
                        next_fb += period
                        if now - next_fb > 0.5:
                            next_fb = now + period
                elif int(self.service.block.state[S.S_TICK]) != self._last_fb_tick:
                    self.send_feedback()   # lockstep/paused: once after every step (REST or SYNC)
                else:
                    self._check_events()
                if now >= next_status:
                    self.send_status()
                    next_status += 0.1
                    if now - next_status > 0.5:
                        next_status = now + 0.1
                if now >= next_hb:
                    self.send_heartbeat()
                    next_hb += 1.0
                    if now - next_hb > 2.0:
                        next_hb = now + 1.0
            except Exception:  # noqa: BLE001
                log.exception("CAN transmit")
            nxt = min(next_fb if mode in ("realtime", "fast") else now + 0.002, next_status, next_hb)
            await asyncio.sleep(max(0.0005, min(nxt - loop.time(), 0.01)))
