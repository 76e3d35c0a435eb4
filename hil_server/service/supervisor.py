"""Engine supervision: start the engine process, watch it, report its death or stall everywhere,
restart it by policy.

A thread of its own waits on the engine's process sentinel and its event pipe every few
milliseconds and checks that the loop's heartbeat word advances (the loop bumps it every tick, and
at least every 10 ms when paused or in lockstep). Death (exit, signal) or a stall longer than
``stall_s`` (time without a heartbeat by the loop's own fault, not the OS's: :mod:`.stall_clock`)
marks the engine down with the reason, kills a stalled one, and calls the ``on_down`` listeners
at once (CAN: feedback stops, NMT stopped, EMCY; recordings closed; commands refused). Policy
``auto`` restarts it from the initial state with every valve neutral, with a growing delay and at
most ``max_per_min`` restarts a minute (then it stays down, as ``never`` does at once), and calls
``on_up``. VeriStand and Speedgoat stop the real-time target on such faults; an emulator
may come back, but only loudly.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from collections import deque
from dataclasses import replace
from multiprocessing.connection import wait

from ..engine.process import EngineClient, EngineDown
from .stall_clock import StallClock

log = logging.getLogger("hydrohil.supervisor")

POLL_S = 0.005
BACKOFF_S = (0.5, 1.0, 2.0, 4.0, 8.0)

RUNNING, RESTARTING, DOWN, STOPPED = "running", "restarting", "down", "stopped"


def describe_exit(code: int | None) -> str:
    if code is None:
        return "still running"
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        return f"killed by {name}"
    return f"exited with status {code}"


def _doing(eng, block, now: float) -> str:
    """What the engine was asked to do when it stalled: its mode and the request it was answering."""
    text = f", mode {block.mode()}"
    flight = eng.in_flight
    if flight is not None:
        text += f", answering {flight[0]!r} sent {1e3 * (now - flight[1]):.0f} ms before"
    return text


class EngineSupervisor:
    def __init__(self, spec_provider, engine_cfg, layout, block, *, restart: str = "auto", max_per_min: int = 5,
                 stall_s: float = 0.1, before_start=None):
        if restart not in ("auto", "never"):
            raise ValueError(f"engine restart policy {restart!r}: auto or never")
        self.spec_provider = spec_provider
        self.engine_cfg = engine_cfg
        self.layout = layout
        self.block = block
        self.policy = restart
        self.max_per_min = max_per_min
        self.stall_s = stall_s
        self.before_start = before_start      # called before every (re)start: neutral commands
        self.engine: EngineClient | None = None
        self.state = STOPPED
        self.reason = ""
        self.kind = ""                       # died | stalled
        self.restarts = 0
        self.failures: dict[str, int] = {}   # by kind, for /metrics
        self.down_since: float | None = None
        self.on_down: list = []              # f(kind, reason)
        self.on_up: list = []                # f(restarts)
        self.on_event: list = []             # f(name, payload) for engine events (diverged)
        self._restart_times: deque = deque()
        self._restart_at: float | None = None
        self._restart_mode = engine_cfg.mode
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # ---- lifecycle --------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the engine (blocks until it runs) and the watcher."""
        self._spawn(self.engine_cfg)
        self._thread = threading.Thread(target=self._watch, name="hydrohil-supervisor", daemon=True)
        self._thread.start()

    def _spawn(self, cfg) -> None:
        self.block.reset_for_engine()
        if self.before_start is not None:
            self.before_start()
        engine = EngineClient(self.spec_provider(), cfg, self.layout, self.block)
        with self._lock:
            if self._stop.is_set():      # the service closed while the engine started
                engine.kill()
                raise EngineDown("the service is stopping")
            self.engine = engine
            self.state = RUNNING
            self.down_since = None

    def close(self) -> None:
        with self._lock:
            self.state = STOPPED
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        if self.engine is not None:
            self.engine.stop()

    # ---- requests -----------------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        return self.state == RUNNING

    def describe(self) -> dict:
        eng = self.engine
        return {"state": self.state, "reason": (self.reason or None) if self.state != RUNNING else None,
                "last_failure": self.reason or None, "restarts": self.restarts,
                "restart_policy": self.policy, "pid": eng.pid if eng is not None and self.state == RUNNING else None,
                "down_for_s": None if self.down_since is None else time.monotonic() - self.down_since}

    def down_message(self) -> str:
        what = {RESTARTING: "engine down (restarting)", DOWN: "engine down", STOPPED: "engine stopped"}.get(self.state, "engine")
        return f"{what}: {self.reason}" if self.reason else what

    def request(self, op: str, *args, timeout: float = 60.0):
        """Forward a control request to the running engine (raises EngineDown, EngineError, TimeoutError)."""
        eng = self.engine
        if self.state != RUNNING or eng is None:
            raise EngineDown(self.down_message())
        return eng.request(op, *args, timeout=timeout)

    # ---- the watcher ----------------------------------------------------------------------------------
    def _watch(self) -> None:
        stall = StallClock(POLL_S)
        while not self._stop.is_set():
            eng = self.engine
            if self.state == RESTARTING and self._restart_at is not None and time.monotonic() >= self._restart_at:
                self._restart()   # here, on this long-lived thread: an engine's PR_SET_PDEATHSIG fires when
                continue          # the thread that started it ends
            if self.state != RUNNING or eng is None:
                self._stop.wait(POLL_S)
                continue
            try:
                ready = wait([eng.process.sentinel, eng.events], timeout=POLL_S)
            except (OSError, ValueError):
                ready = []
            if eng.events in ready:
                self._drain_events(eng)
            if self.state != RUNNING or self.engine is not eng:
                continue
            now = time.monotonic()
            if not eng.process.is_alive():
                self._fail(eng, "died", f"engine process {describe_exit(eng.process.exitcode)}")
                stall.reset()
                continue
            idle = stall.no_progress_s(self.block.beat(), now, eng.pid, self.block.wake_s())
            if idle > self.stall_s:
                self._fail(eng, "stalled", f"engine loop made no progress for {1e3 * idle:.0f} ms "
                                           f"(limit {1e3 * self.stall_s:.0f} ms{_doing(eng, self.block, now)}); killed")
                stall.reset()

    def _drain_events(self, eng) -> None:
        try:
            while eng.events.poll():
                name, payload = eng.events.recv()
                for cb in list(self.on_event):
                    try:
                        cb(name, payload)
                    except Exception:  # noqa: BLE001
                        log.exception("engine event listener")
        except (EOFError, OSError, ValueError):
            pass

    def _fail(self, eng, kind: str, reason: str) -> None:
        with self._lock:
            if self.state != RUNNING or self.engine is not eng:
                return
            self.state = RESTARTING if self.policy == "auto" else DOWN
            self.kind, self.reason = kind, reason
            self.down_since = time.monotonic()
            self.failures[kind] = self.failures.get(kind, 0) + 1
        last_mode = self.block.mode()
        eng.kill()
        log.error("%s", self.down_message())
        for cb in list(self.on_down):
            try:
                cb(kind, reason)
            except Exception:  # noqa: BLE001 - every listener gets its chance
                log.exception("engine-down listener")
        if self.policy == "auto":
            self._schedule_restart(last_mode)

    def _schedule_restart(self, mode: str) -> None:
        now = time.monotonic()
        while self._restart_times and now - self._restart_times[0] > 60.0:
            self._restart_times.popleft()
        if len(self._restart_times) >= self.max_per_min:
            with self._lock:
                self.state = DOWN
                self.reason += f"; not restarted: {len(self._restart_times)} restarts in the last minute"
            log.error("%s", self.down_message())
            return
        self._restart_mode = mode
        self._restart_at = now + BACKOFF_S[min(len(self._restart_times), len(BACKOFF_S) - 1)]

    def _restart(self) -> None:
        self._restart_at = None
        self._restart_times.append(time.monotonic())
        try:
            self._spawn(replace(self.engine_cfg, mode=self._restart_mode))
        except Exception as exc:  # noqa: BLE001 - the engine would not start again: stay down, say why
            with self._lock:
                if self._stop.is_set():
                    return
                self.state = DOWN
                self.reason += f"; restart failed: {str(exc).splitlines()[0]}"
            log.error("%s", self.down_message())
            return
        with self._lock:
            self.restarts += 1
        log.warning("engine restarted (%d restart%s so far) after: %s; initial state, every valve neutral",
                    self.restarts, "" if self.restarts == 1 else "s", self.reason)
        for cb in list(self.on_up):
            try:
                cb(self.restarts)
            except Exception:  # noqa: BLE001
                log.exception("engine-up listener")
