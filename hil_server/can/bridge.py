"""CAN bridge: ValveCommand frames in; JointFeedback / JointPressure / HilStatus / EngineStatus /
Heartbeat / EMCY out.

Everything runs on one asyncio event loop (uvicorn's under ``hydrohil serve``): no CAN thread
competes with the REST server for the GIL. Blocking engine calls (a lockstep step per SYNC) run on a
worker thread of their own, never on the loop.

Receive: every frame passes its id's flood budget first (:mod:`.flood`; frames beyond it are
dropped, counted, and reported by EMCY 0x8110 at most once a second per id). A command frame with
the right DLC, an in-range voltage and a good alive counter (:mod:`.alive_counter`) becomes the
joint's command (source CAN, so the engine's watchdog guards it). SYNC advances the plant one tick
in lockstep mode and answers with feedback; commands that arrive while SYNCs are pending are
applied in bus order after them. Anything else (wrong DLC, unknown id, remote or error frames,
out-of-range commands) is counted and ignored; the plant runs in its own process, so a flood cannot
slow its loop. While the engine is down or the plant diverged, commands are counted and ignored.

Transmit task: cyclic feedback at ``feedback_rate`` in realtime/fast modes, only with a tick newer
than the last one sent (never a stale frame; in lockstep and paused, once after every step), status
at 10 Hz, heartbeat at 1 Hz, and EMCY when a watchdog trip, fault or counter error starts (error
code) or ends (0x0000). Engine death or stall (told by the supervisor): feedback stops at once,
EMCY 0x6100/0x6101, heartbeat NMT stopped, HilStatus state engine_down; a restarted engine:
heartbeat boot-up, EMCY reset.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor

import can
import numpy as np

from ..engine import shared as S
from ..service.config import ServiceError
from . import dbc as D
from .alive_counter import OK as COUNTER_OK
from .alive_counter import AliveCounters
from .flood import IdRateLimiter
from .transports import open_transport

log = logging.getLogger("hydrohil.can")

FLOOD_RATE = 5000.0    # frames/s admitted per CAN id (burst: 0.1 s worth); a 1 Mbit/s bus carries ~8000 in all
NA_ANGLE = 0x7FFF
NA_VOLT = 0xFFFF
ENGINE_STATES = {"running": D.ENGINE_RUNNING, "restarting": D.ENGINE_RESTARTING, "down": D.ENGINE_DOWN,
                 "stopped": D.ENGINE_STOPPED}


class CanBridge:
    def __init__(self, service, spec_str: str, feedback_rate: float | None = None):
        self.service = service
        self.spec_str = spec_str
        spec = service.params.spec
        self.db = D.load_database_for(spec)
        joints = spec.joint_names
        self.joints = joints
        self.cmd_msgs = {}
        for a, j in enumerate(joints):
            m = self.db.get_message_by_name(f"ValveCommand_{j}")
            self.cmd_msgs[m.frame_id] = (a, m)
        self.fb_msgs = [self.db.get_message_by_name(f"JointFeedback_{j}") for j in joints]
        self.pr_msgs = [self.db.get_message_by_name(f"JointPressure_{j}") for j in joints]
        self.status_msg = self.db.get_message_by_name("HilStatus")
        self.engine_msg = self.db.get_message_by_name("EngineStatus")
        self.emcy_msg = self.db.get_message_by_name("Emergency")
        self.hb_msg = self.db.get_message_by_name("Heartbeat")
        self.sync_id = self.db.get_message_by_name("Sync").frame_id
        self.sensed = [spec.joint(j).sensed for j in joints]
        self.dof_index = [spec.tree.index(spec.joint(j).dof) for j in joints]
        self.feedback_rate = feedback_rate or service.cfg.feedback_rate_hz
        self.counters: dict[tuple[str, str], int] = {}
        self.limiter = IdRateLimiter(FLOOD_RATE)
        self.alive = AliveCounters(len(joints), service.cfg.alive_counter_limit)
        self._fb_counter = 0
        self._last_fb_tick = -1
        self._wd_prev = np.zeros(len(joints))
        self._trips_prev = np.zeros(len(joints))
        self._faults_prev: set[str] = set()
        self._diverged_prev = False
        self._occurrence: dict[tuple, int] = {}
        self._engine_error = 0             # EMCY code of the last engine failure
        self._seq: deque = deque()         # frames waiting behind a SYNC, in bus order
        self._seq_busy = False
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="hydrohil-can-sync")
        self.transport = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self._tx_task: asyncio.Task | None = None
        self._boot_up_pending = False

    # ---- lifecycle (coroutines: run on the bridge's event loop) ---------------------------------
    async def start(self) -> None:
        self.loop = asyncio.get_running_loop()
        self.transport = open_transport(self.spec_str)
        if hasattr(self.transport, "admit"):
            self.transport.admit = self.admit   # lets the transport drop a flood before decoding it
        await self.transport.start(self._handle_safe)
        self._tx_task = asyncio.create_task(self._tx_loop())
        log.info("CAN on %s", self.spec_str)
        for w in getattr(self.transport, "warnings", ()):
            log.warning("CAN: %s", w)

    async def close(self) -> None:
        if self._tx_task is not None:
            self._tx_task.cancel()
            try:
                await self._tx_task
            except (asyncio.CancelledError, Exception):  # noqa: BLE001
                pass
        if self.transport is not None:
            await self.transport.close()
        self._worker.shutdown(wait=False, cancel_futures=True)

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

    # ---- supervision (called from the supervisor's thread) ----------------------------------------
    def _on_loop(self, fn, *args) -> None:
        if self.loop is not None and not self.loop.is_closed():
            self.loop.call_soon_threadsafe(fn, *args)

    def engine_down(self, kind: str, reason: str) -> None:
        self._on_loop(self._engine_down, kind)

    def engine_up(self, restarts: int) -> None:
        self._on_loop(self._engine_up)

    def _engine_down(self, kind: str) -> None:
        code = D.EMCY_ENGINE_STALLED if kind == "stalled" else D.EMCY_ENGINE_DIED
        self._engine_error = code
        self._emcy(code, None, D.EMCY_CODES[code][0])
        self.send_heartbeat()
        self.send_status()

    def _engine_up(self) -> None:
        self._last_fb_tick = -1
        self._wd_prev[:] = 0.0
        self._trips_prev[:] = 0.0
        self._diverged_prev = False
        self._send(self.hb_msg, {"nmt_state": D.NMT_BOOT_UP}, "heartbeat")   # CiA 301: a restarted node boots up
        self._emcy(D.EMCY_RESET, None, D.EMCY_CODES[self._engine_error or D.EMCY_ENGINE_DIED][0])
        self.send_status()

    # ---- receive -------------------------------------------------------------------------------
    def _handle_safe(self, msg: can.Message, admitted: bool = False) -> bool:
        try:
            return self.handle(msg, admitted)
        except Exception:  # noqa: BLE001 - a bad frame must never stop the bridge
            self.count("rx", "malformed")
            log.exception("frame %s", msg)
            return False

    def admit(self, arbitration_id: int, extended: bool) -> bool:
        """The frame id's flood budget: False (counted, EMCY 0x8110 at most once a second per id)
        when the frame is to be dropped."""
        key = self.limiter.key(arbitration_id, extended)
        now = time.monotonic()
        if self.limiter.admit(key, now):
            return True
        self.count("rx", "flood_dropped")
        if self.limiter.report_due(key, now):
            self._emcy(D.EMCY_CAN_OVERRUN, None, D.EMCY_CODES[D.EMCY_CAN_OVERRUN][0])
        return False

    def handle(self, msg: can.Message, admitted: bool = False) -> bool:
        """Process one received frame; False when it was dropped as flood (a gateway transport then
        does not forward it to its other clients). ``admitted``: the transport already asked
        :meth:`admit`."""
        if not admitted and not self.admit(msg.arbitration_id, msg.is_extended_id):
            return False
        if msg.is_error_frame:
            self.count("rx", "error_frame")
            return True
        if msg.is_remote_frame:
            self.count("rx", "remote_frame")
            return True
        fid = msg.arbitration_id
        entry = self.cmd_msgs.get(fid) if not msg.is_extended_id else None
        if entry is not None:
            self._command(entry, msg)
            return True
        if fid == self.sync_id and not msg.is_extended_id:
            if msg.dlc > 1:
                self.count("rx", "wrong_dlc")
                return True
            self.count("rx", "sync")
            if self.service.control.mode == "lockstep":
                self._seq.append(None)
                self._kick_seq()
            return True
        self.count("rx", "unknown_id")
        return True

    def _command(self, entry, msg: can.Message) -> None:
        a, m = entry
        if msg.dlc != m.length:
            self.count("rx", "wrong_dlc")
            self._emcy(D.EMCY_LENGTH, a, D.FMI_ERRATIC)
            return
        sig = m.decode(bytes(msg.data), decode_choices=False)
        volts = sig["voltage"]
        lo, hi = self.service.params.spec.joint(self.joints[a]).command_range
        if not lo <= volts <= hi:
            self.count("rx", "out_of_range")
            self._emcy(D.EMCY_RANGE, a, D.FMI_ABOVE)
            return
        was_lost = self.alive.lost[a]
        what, apply = self.alive.check(a, int(sig["counter"]))
        if what != COUNTER_OK:
            self.count("rx", f"counter_{what}")
        if not apply:
            self.count("rx", "counter_lost")
            if not was_lost:
                self._emcy(D.EMCY_ALIVE_COUNTER, a, D.FMI_NETWORK_DATA)
            return
        if was_lost:
            self._emcy(D.EMCY_RESET, a, D.FMI_NETWORK_DATA)
        if self._seq or self._seq_busy:
            self._seq.append((a, float(volts)))   # behind a pending SYNC: keep bus order
            return
        self._apply(a, float(volts))

    def _apply(self, a: int, volts: float) -> None:
        svc = self.service
        if not svc.supervisor.running:
            self.count("rx", "engine_down")
            return
        if svc.block.state[S.S_DIVERGED]:
            self.count("rx", "diverged")
            return
        svc.commands.write({a: volts}, S.SRC_CAN)
        self.count("rx", "command")

    def _kick_seq(self) -> None:
        if not self._seq_busy:
            self._seq_busy = True
            asyncio.get_running_loop().create_task(self._run_seq())

    async def _run_seq(self) -> None:
        """SYNCs and the commands queued behind them, in bus order; each step on the worker thread."""
        loop = asyncio.get_running_loop()
        try:
            while self._seq:
                item = self._seq.popleft()
                if item is not None:
                    self._apply(*item)
                    continue
                try:
                    await loop.run_in_executor(self._worker, self.service.control.step, 1)
                except ServiceError as exc:
                    self.count("rx", "sync_refused")
                    log.debug("SYNC refused: %s", exc)
                    continue
                self.send_feedback()
        finally:
            self._seq_busy = False

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
        if not svc.supervisor.running:
            return
        try:
            snap = svc.block.snapshot()
        except S.SnapshotError:
            self.count("tx", "feedback_unreadable")
            return
        n = svc.block.layout.n_dof
        act = snap[S.S_HDR + 2 * n:].reshape(svc.block.layout.n_act, S.A_N)
        qd = snap[S.S_HDR + n:S.S_HDR + 2 * n]
        estop = snap[S.S_ESTOP] != 0.0
        diverged = snap[S.S_DIVERGED] != 0.0
        faulted = {f["joint"] for f in svc.faults.active.values()}
        spec = svc.params.spec
        self._fb_counter = (self._fb_counter + 1) & 0xFF
        frames = []
        for a, j in enumerate(self.joints):
            status = (D.STATUS_WATCHDOG if act[a, S.A_WATCHDOG] else 0) \
                | (D.STATUS_FAULT if (j in faulted or diverged) else 0) \
                | (D.STATUS_ESTOP if estop else 0) | (0 if self.sensed[a] else D.STATUS_NOT_SENSED)
            vel = float(np.clip(qd[self.dof_index[a]], -32.7, 32.7))
            if self.sensed[a]:
                fb = {"angle": float(np.clip(act[a, S.A_ANGLE], -3.2767, 3.2767)),
                      "sensor_voltage": float(np.clip(act[a, S.A_SENS_V], 0.0, 13.1)),
                      "velocity": vel, "status": status, "counter": self._fb_counter}
            else:
                fb = {"angle": NA_ANGLE * 1e-4, "sensor_voltage": NA_VOLT * 2e-4, "velocity": vel,
                      "status": status, "counter": self._fb_counter}
            frames.append(self._frame(self.fb_msgs[a], fb))
            lo, hi = spec.joint(j).command_range
            frames.append(self._frame(self.pr_msgs[a], {
                "pressure_a": float(np.clip(act[a, S.A_P_A], 0.0, 65.5e6)),
                "pressure_b": float(np.clip(act[a, S.A_P_B], 0.0, 65.5e6)),
                "command_voltage": float(np.clip(act[a, S.A_U], lo, hi)),
                "spool": float(np.clip(act[a, S.A_SPOOL], -1.28, 1.27)),
                "counter": self._fb_counter}))
        self._send_frames(frames, "feedback")
        self._last_fb_tick = int(snap[S.S_TICK])
        self._check_events(act)

    def hil_state(self) -> int:
        svc = self.service
        if not svc.supervisor.running:
            return D.HIL_ENGINE_DOWN
        st = svc.block.state
        if st[S.S_ESTOP]:
            return D.HIL_ESTOP
        if st[S.S_DIVERGED]:
            return D.HIL_DIVERGED
        if svc.faults.active:
            return D.HIL_FAULT
        return D.HIL_WATCHDOG if np.any(svc.block.act[:, S.A_WATCHDOG]) else D.HIL_OK

    def send_status(self) -> None:
        svc = self.service
        st = svc.block.state
        running = svc.supervisor.running
        mask = 0
        if running:
            for a in np.flatnonzero(svc.block.act[:, S.A_WATCHDOG]):
                mask |= 1 << int(a)
        sup = svc.supervisor.describe()
        self._send_frames([
            self._frame(self.status_msg, {"mode": int(st[S.S_MODE]), "state": self.hil_state(), "watchdog_mask": mask,
                                          "tick": int(st[S.S_TICK]) & 0xFFFF}),
            self._frame(self.engine_msg, {"engine_state": ENGINE_STATES.get(sup["state"], D.ENGINE_DOWN),
                                          "restarts": min(sup["restarts"], 0xFFFF), "error_code": self._engine_error,
                                          "diverged": int(bool(st[S.S_DIVERGED]) and running)}),
        ], "status")

    def send_heartbeat(self) -> None:
        if not self.service.supervisor.running:
            nmt = D.NMT_STOPPED
        else:
            nmt = D.NMT_OPERATIONAL if self.service.control.mode in ("realtime", "fast", "lockstep") \
                else D.NMT_PRE_OPERATIONAL
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
        svc = self.service
        if not svc.supervisor.running:
            return
        act = svc.block.act if act is None else act
        wd = act[:, S.A_WATCHDOG].copy()
        trips = act[:, S.A_WD_TRIPS].copy()
        # every trip gets its EMCY, also one that started and ended between two looks
        for a in np.flatnonzero((trips != self._trips_prev) | (wd != self._wd_prev)):
            if trips[a] != self._trips_prev[a]:
                self._emcy(D.EMCY_TIMEOUT, int(a), D.FMI_TIMEOUT)
            if not wd[a]:
                self._emcy(D.EMCY_RESET, int(a), D.FMI_TIMEOUT)
        self._wd_prev, self._trips_prev = wd, trips
        faults = set(svc.faults.active)
        for fid in faults - self._faults_prev:
            f = svc.faults.active.get(fid)
            if f:
                j = f["joint"]
                self._emcy(D.EMCY_HARDWARE, None if j is None else self.joints.index(j), D.FMI_BAD_DEVICE)
        for fid in self._faults_prev - faults:
            kind, _, j = fid.partition(":")
            self._emcy(D.EMCY_RESET, self.joints.index(j) if j in self.joints else None, D.FMI_BAD_DEVICE)
        self._faults_prev = faults
        diverged = bool(svc.block.state[S.S_DIVERGED])
        if diverged != self._diverged_prev:
            self._emcy(D.EMCY_DIVERGED if diverged else D.EMCY_RESET, None, D.EMCY_CODES[D.EMCY_DIVERGED][0])
            self._diverged_prev = diverged

    async def _tx_loop(self) -> None:
        period = 1.0 / self.feedback_rate
        loop = asyncio.get_running_loop()
        next_fb = next_status = next_hb = loop.time()
        svc = self.service
        while True:
            now = loop.time()
            running = svc.supervisor.running
            mode = svc.control.mode
            cyclic = running and mode in ("realtime", "fast")
            try:
                if cyclic:
                    if now >= next_fb:
                        if int(svc.block.state[S.S_TICK]) != self._last_fb_tick:   # never a stale frame
                            self.send_feedback()
                        else:
                            self.count("tx", "stale_suppressed")
                        next_fb += period
                        if now - next_fb > 0.5:
                            next_fb = now + period
                elif running and not self._seq_busy and int(svc.block.state[S.S_TICK]) != self._last_fb_tick:
                    self.send_feedback()   # lockstep/paused: once after every REST step
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
            nxt = min(next_fb if cyclic else now + 0.002, next_status, next_hb)
            await asyncio.sleep(max(0.0005, min(nxt - loop.time(), 0.01)))
