"""The engine process: owns the plant's Context, runs the loop, answers control requests.

Started with the ``spawn`` method (the service has threads), it raises itself to SCHED_FIFO when the
OS permits (research note: only a separate SCHED_FIFO process kept p99 lateness < 100 us beside a
loaded HTTP server) and says so in the state; otherwise it runs anyway at normal priority.
"""

from __future__ import annotations

import ctypes
import logging
import multiprocessing as mp
import os
import pickle
import signal
import threading
import time
import traceback
from dataclasses import dataclass

import numpy as np

from . import atomics as A
from . import shared as S

log = logging.getLogger("hydrohil.engine")

RT_PRIORITY = 50
PR_SET_PDEATHSIG = 1
PR_SET_TIMERSLACK = 29


@dataclass
class EngineConfig:
    rate_hz: float = 1000.0
    mode: str = "realtime"
    watchdog_ms: float = 100.0
    seed: int = 0
    realtime_priority: bool = True
    cpu: int | None = None  # pin the engine to a CPU (None: leave to the OS)


def _raise_priority(cfg: EngineConfig) -> tuple[bool, str]:
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(PR_SET_TIMERSLACK, 1, 0, 0, 0)  # 1 ns timer slack: wake-ups on time
    except OSError:
        pass
    if cfg.cpu is not None:
        try:
            os.sched_setaffinity(0, {cfg.cpu})
        except (OSError, AttributeError):
            pass
    if not cfg.realtime_priority:
        return False, "real-time priority disabled by configuration"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
        return True, f"SCHED_FIFO priority {RT_PRIORITY}"
    except (PermissionError, OSError, AttributeError) as exc:
        return False, f"real-time priority not permitted ({exc}); running at normal priority"


def _normal_priority() -> None:
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (PermissionError, OSError, AttributeError):
        pass


def _die_with_parent(parent_pid: int) -> None:
    """A real-time process must not outlive its service: an orphaned SCHED_FIFO engine would keep
    spinning and starve the machine. The kernel sends SIGKILL when the parent exits."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except OSError:
        pass
    if os.getppid() != parent_pid:   # the parent died before prctl took effect
        os._exit(1)


def engine_main(spec_blob: bytes, cfg: EngineConfig, shm_name: str, layout: S.Layout, conn, events,
                parent_pid: int = 0) -> None:
    """Entry point of the engine process. ``conn``: requests in, replies out (each tagged with its
    request id); ``events``: one-way notices to the service's supervisor."""
    if parent_pid:
        _die_with_parent(parent_pid)
    from sim_core.kernel.compile_notice import notice, on_kernel_compile
    from sim_core.plant import Plant
    from sim_core.simulator import Simulator

    from .loop import EngineLoop

    block = S.SharedBlock(layout, name=shm_name)
    block.prefault()   # map every page now, not with a page fault inside a tick (the recording ring: ~12 MB)
    try:
        spec = pickle.loads(spec_blob)
        plant = Plant(spec)
        # a kernel numba has not cached yet is compiled here: say so, the service then waits for it
        with on_kernel_compile(lambda: conn.send((None, "compiling", {"notice": notice()}))):
            warm = Simulator(plant.create_context())
            warm.step(np.zeros(len(spec.joints)), 1.0 / cfg.rate_hz)  # load the compiled kernel before timing
        ctx = plant.create_context(seed=cfg.seed)
        sim = Simulator(ctx)
        rt, note = _raise_priority(cfg)
        loop = EngineLoop(ctx, sim, block, conn, dt=1.0 / cfg.rate_hz, mode=cfg.mode,
                          watchdog_s=cfg.watchdog_ms / 1000.0, realtime_priority=rt, events=events)
        loop.handlers = ControlHandler(loop, conn, cfg)
        if cfg.mode != "realtime":
            _normal_priority()   # only realtime has deadlines; a long lockstep step must not starve the host
        import gc

        gc.collect()
        gc.freeze()   # a full collection of the start-up heap in the loop would be a ~50 ms overrun
        conn.send((None, "ready", {"realtime_priority": rt, "priority_note": note, "pid": os.getpid()}))
        loop.run()
    except Exception as exc:  # report start-up failures to the service instead of dying silently
        try:
            conn.send((None, "error", f"engine failed: {exc}\n{traceback.format_exc()}"))
        except OSError:
            pass
    finally:
        block.state[S.S_ALIVE] = 0.0
        block.close()


class ControlHandler:
    """Applies one control request between ticks and replies on the pipe with the request's id."""

    def __init__(self, loop, conn, cfg: EngineConfig):
        self.loop = loop
        self.conn = conn
        self.cfg = cfg

    def __call__(self, msg) -> None:
        try:
            rid, op, args = msg
            handler = getattr(self, "op_" + op)
        except (TypeError, ValueError, AttributeError):
            self.conn.send((None, "error", f"malformed request {msg!r:.200}"))
            return
        try:
            self.conn.send((rid, "ok", handler(*args)))
        except Exception as exc:  # noqa: BLE001 - the service turns this into a 4xx
            self.conn.send((rid, "error", str(exc)))

    def op_mode(self, mode: str):
        if mode not in S.MODES:
            raise ValueError(f"unknown mode {mode!r}")
        if mode != "realtime":
            _normal_priority()
        elif self.loop.mode != "realtime":
            _raise_priority(self.cfg)
        self.loop.mode = mode
        self.loop.block.state[S.S_MODE] = S.MODES.index(mode)
        return {"mode": mode}

    def op_step(self, n: int):
        if self.loop.mode != "lockstep":
            raise RuntimeError(f"step needs lockstep mode (mode is {self.loop.mode})")
        self.loop.run_ticks(int(n))
        return {"tick": self.loop.tick_count, "time": self.loop.ctx.time}

    def op_reset(self, seed):
        self.loop.ctx.reset(seed)
        self.loop.clear_diverged()
        self.loop._publish()
        return {"time": self.loop.ctx.time}

    def op_set_parameters(self, values: dict):
        ctx = self.loop.ctx
        old = {p: ctx.get_parameter(p) for p in values}
        try:
            for p, v in values.items():
                ctx.set_parameter(p, v)
        except Exception:
            for p, v in old.items():
                ctx.set_parameter(p, v)
            raise
        return {p: ctx.get_parameter(p) for p in values}

    def op_enable_effect(self, name, joint, params):
        inst = self.loop.ctx.enable_effect(name, joint, **params)
        return inst.to_dict()

    def op_disable_effect(self, name, joint):
        return {"changed": self.loop.ctx.disable_effect(name, joint)}

    def op_set_fault(self, joint, kind, params):
        self.loop.ctx.set_fault(joint, kind, **params)
        return {}

    def op_clear_fault(self, joint, kind):
        return {"cleared": self.loop.ctx.clear_fault(joint, kind)}

    def op_clear_faults(self):
        self.loop.ctx.clear_faults()
        return {}

    def op_record(self, on: bool):
        b = self.loop.block
        if on:
            A.store_release(b.sync, S.W_REC_ROWS, 0)
        self.loop.recording = bool(on)
        return {"rows": b.rec_rows()}

    def op_stop(self):
        self.loop.stop = True
        self.loop.recording = False
        return {"tick": self.loop.tick_count}


class EngineError(RuntimeError):
    """The engine refused a request (bad parameter, wrong mode, ...); the message says why."""


class EngineDown(RuntimeError):
    """The engine process is not running (died, stalled and killed, stopped, restarting)."""


COMPILE_TIMEOUT_S = 1800.0   # s; a first compile of the kernel takes 1-3 min on a 2-core machine


class EngineStartError(RuntimeError):
    """The engine process did not come up: it failed, exited or stayed silent past its time."""


def await_ready(conn, process, start_timeout: float, compile_timeout: float = COMPILE_TIMEOUT_S) -> dict:
    """Wait for the engine's ``ready`` on ``conn`` and return its info. The engine has
    ``start_timeout`` seconds; once it says it is compiling the kernel (numba had none cached for
    this robot), ``compile_timeout`` from then: a first compile is slow, not hung."""
    timeout, compiling = start_timeout, False
    while True:
        if not conn.poll(timeout):
            process.kill()
            if compiling:
                raise EngineStartError(f"engine did not finish compiling the simulation kernel within {timeout:.0f} s")
            raise EngineStartError(f"engine did not start within {timeout:.0f} s")
        try:
            _, kind, info = conn.recv()
        except EOFError:
            process.join(1.0)
            raise EngineStartError(f"engine process exited during start-up (exit code {process.exitcode})") from None
        if kind == "compiling":
            log.info("%s", info["notice"])
            timeout, compiling = max(start_timeout, compile_timeout), True
            continue
        if kind != "ready":
            process.join(5.0)
            raise EngineStartError(str(info))
        return info


class EngineClient:
    """Service-side handle: starts the engine process and sends it requests (thread-safe).

    Every request carries an id and only the reply with that id answers it: a reply that arrives
    after its request timed out, or an unsolicited message from a dying engine, is counted and
    dropped, never taken as the answer to a later request."""

    def __init__(self, spec, cfg: EngineConfig, layout: S.Layout, block: S.SharedBlock, start_timeout: float = 120.0,
                 compile_timeout: float = COMPILE_TIMEOUT_S):
        self.cfg = cfg
        self.block = block
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self.events, child_events = ctx.Pipe(duplex=False)
        self._lock = threading.Lock()
        self._next_id = 0
        self.dropped_replies = 0
        self.in_flight: tuple[str, float] | None = None   # (op, monotonic s sent): a stall's likely cause
        self.process = ctx.Process(target=engine_main, args=(pickle.dumps(spec), cfg, block.name, layout, child,
                                                             child_events, os.getpid()),
                                   name="hydrohil-engine", daemon=True)
        self.process.start()
        child.close()
        child_events.close()
        self.info = await_ready(self._conn, self.process, start_timeout, compile_timeout)

    @property
    def pid(self) -> int | None:
        return self.process.pid

    def request(self, op: str, *args, timeout: float = 60.0):
        with self._lock:
            if not self.process.is_alive():
                raise EngineDown("engine process is not running")
            self._next_id += 1
            rid = self._next_id
            try:
                self._conn.send((rid, op, args))
            except (OSError, ValueError) as exc:
                raise EngineDown(f"engine control channel closed ({exc})") from None
            A.fetch_add(self.block.sync, S.W_CTL, 1)   # tells the realtime loop to look at the pipe
            self.in_flight = (op, time.monotonic())
            try:
                end = time.monotonic() + timeout
                while True:
                    left = end - time.monotonic()
                    if left <= 0 or not self._conn.poll(left):
                        raise TimeoutError(f"engine did not answer {op!r} within {timeout:g} s")
                    try:
                        msg = self._conn.recv()
                    except (EOFError, OSError):
                        raise EngineDown(f"engine process ended while answering {op!r}") from None
                    if isinstance(msg, tuple) and len(msg) == 3 and msg[0] == rid:
                        _, kind, payload = msg
                        break
                    self.dropped_replies += 1
            finally:
                self.in_flight = None
        if kind == "error":
            raise EngineError(payload)
        return payload

    def stop(self, timeout: float = 5.0) -> None:
        if self.process.is_alive():
            try:
                self.request("stop", timeout=timeout)
            except (RuntimeError, TimeoutError, OSError, EOFError):
                pass
            self.process.join(timeout)
        self.kill()

    def kill(self) -> None:
        if self.process.is_alive():
            self.process.kill()
            self.process.join(2.0)
        for c in (self._conn, self.events):
            try:
                c.close()
            except OSError:
                pass
