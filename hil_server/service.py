"""HilService: the composition root of the emulator (engine process, commands, state, recordings,
CAN bridge, viewer plugins). REST routers and transports talk to this object only."""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path

import numpy as np

from sim_core.params_file import ParamsFileError, apply_params_file
from sim_core.effects import catalog
from sim_core.model.spec import RobotSpec, SpecError, load_robot

from .channels import ChannelMap
from .engine import shared as S
from .engine.process import EngineClient, EngineConfig, EngineError
from .recorder import Recorder

log = logging.getLogger("hydrohil.service")

SOURCES = {S.SRC_NONE: "none", S.SRC_REST: "rest", S.SRC_CAN: "can", S.SRC_VIEWER: "viewer"}


class ServiceError(ValueError):
    """A request the service refuses (the API maps it to 4xx with this message)."""

    def __init__(self, msg: str, status: int = 422):
        super().__init__(msg)
        self.status = status


@dataclass
class ServiceConfig:
    robot: str = "mars_nd"
    host: str = "127.0.0.1"
    port: int = 8000
    can: str | None = "socketcand:29536"
    viewer_port: int | None = 8080
    rate_hz: float = 1000.0
    mode: str = "realtime"
    params: str | None = None
    token: str | None = None
    watchdog_ms: float = 100.0
    feedback_rate_hz: float = 100.0
    recordings_dir: str = "recordings"
    seed: int = 0
    node_id: int = 0x10
    realtime_priority: bool = True
    recording_ring_s: float = 60.0
    engine_cpu: int | None = None
    extra: dict = field(default_factory=dict)


class HilService:
    def __init__(self, cfg: ServiceConfig):
        if not 1.0 <= cfg.rate_hz <= 20000.0:
            raise ServiceError(f"--rate {cfg.rate_hz}: must be between 1 and 20000 Hz")
        if cfg.mode not in S.MODES:
            raise ServiceError(f"--mode {cfg.mode!r}: one of {', '.join(S.MODES)}")
        if cfg.can:
            from .can.transports import check_spec

            try:
                check_spec(cfg.can)
            except ValueError as exc:
                raise ServiceError(f"--can {cfg.can}: {exc}") from None
        self.cfg = cfg
        spec = load_robot(cfg.robot)
        if cfg.params:
            try:
                apply_params_file(spec, cfg.params)
            except ParamsFileError as exc:
                raise ServiceError(str(exc)) from None
        self.spec: RobotSpec = spec       # mirror of the engine's parameters, validated here first
        self.channels = ChannelMap(spec)
        self.joint_index = {j: a for a, j in enumerate(spec.joint_names)}
        self.dt = 1.0 / cfg.rate_hz
        self.layout = S.Layout(spec.tree.n, len(spec.joints), len(spec.sensed_joints),
                               max(1000, int(cfg.recording_ring_s * cfg.rate_hz)))
        self.block = S.SharedBlock(self.layout)
        self._cmd_lock = threading.Lock()
        self._param_lock = threading.Lock()
        self.faults: dict[str, dict] = {}
        self.started = time.time()
        self.engine = EngineClient(spec, EngineConfig(rate_hz=cfg.rate_hz, mode=cfg.mode, watchdog_ms=cfg.watchdog_ms,
                                                      seed=cfg.seed, realtime_priority=cfg.realtime_priority,
                                                      cpu=cfg.engine_cpu), self.layout, self.block)
        self.recorder = Recorder(self.block, spec, Path(cfg.recordings_dir), self.engine)
        self.metrics = Metrics()
        self.bridge = None
        self._can_loop: asyncio.AbstractEventLoop | None = None
        self._can_thread: threading.Thread | None = None
        self.plugins: list = []
        self._pct_cache = (0.0, {})
        self._closed = False

    # ---- lifecycle -------------------------------------------------------------------------
    def start_transports(self) -> None:
        """Start CAN (on an event-loop thread of its own) and viewer plugins: for embedding the
        service without an event loop. ``hydrohil serve`` uses :meth:`start_transports_async`."""
        if self.cfg.can:
            self._can_loop = asyncio.new_event_loop()
            self._can_thread = threading.Thread(target=self._can_loop.run_forever, name="can-loop", daemon=True)
            self._can_thread.start()
            asyncio.run_coroutine_threadsafe(self._start_bridge(), self._can_loop).result(30)
        self._start_viewers()

    async def start_transports_async(self) -> None:
        """Start CAN on the running loop (uvicorn's: CAN and REST share one thread, no GIL hand-offs)."""
        if self.cfg.can:
            await self._start_bridge()
        self._start_viewers()

    async def _start_bridge(self) -> None:
        from .can.bridge import CanBridge

        bridge = CanBridge(self, self.cfg.can)
        await bridge.start()
        self.bridge = bridge

    def _start_viewers(self) -> None:
        if self.cfg.viewer_port:
            for ep in entry_points(group="hydrohil.viewers"):
                try:
                    self.plugins.append(ep.load()(self, self.cfg.viewer_port))
                except Exception as exc:  # the plant keeps running without its viewer
                    log.error("viewer plugin %s failed: %s", ep.name, exc)

    async def close_transports_async(self) -> None:
        if self.bridge is not None and self._can_loop is None:
            bridge, self.bridge = self.bridge, None
            await bridge.close()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for p in self.plugins:
            try:
                p.close()
            except Exception:  # noqa: BLE001
                pass
        if self.bridge is not None and self._can_loop is not None:
            try:
                asyncio.run_coroutine_threadsafe(self.bridge.close(), self._can_loop).result(5)
            except Exception:  # noqa: BLE001
                pass
            self._can_loop.call_soon_threadsafe(self._can_loop.stop)
            self._can_thread.join(5)
        self.bridge = None
        try:
            self.recorder.close()
        finally:
            self.engine.stop()
            self.block.close()

    # ---- commands ---------------------------------------------------------------------------
    def validate_voltages(self, voltages: dict[str, float]) -> dict[int, float]:
        out = {}
        for j, v in voltages.items():
            if j not in self.joint_index:
                raise ServiceError(f"unknown joint {j!r}; joints: {', '.join(self.spec.joint_names)}")
            if not np.isfinite(v):
                raise ServiceError(f"joint {j}: voltage must be a finite number")
            lo, hi = self.spec.joint(j).command_range
            if not lo <= v <= hi:
                raise ServiceError(f"joint {j}: {v:g} V is outside the command range [{lo:g}, {hi:g}] V")
            out[self.joint_index[j]] = float(v)
        return out

    def set_voltages(self, voltages: dict[str, float], source: float = S.SRC_REST) -> dict[str, float]:
        checked = self.validate_voltages(voltages)
        self.write_commands(checked, source)
        return {self.spec.joint_names[a]: v for a, v in checked.items()}

    def write_commands(self, by_index: dict[int, float], source: float) -> None:
        """Write already validated commands (the CAN bridge calls this directly)."""
        now = time.monotonic()
        t_sim = float(self.block.state[S.S_TIME])
        with self._cmd_lock:
            S.SharedBlock.write_begin(self.block.cmd_seq)
            for a, v in by_index.items():
                self.block.cmd[a, S.C_VOLT] = v
                self.block.cmd[a, S.C_SOURCE] = source
                self.block.cmd[a, S.C_T_WALL] = now
                self.block.cmd[a, S.C_T_SIM] = t_sim
            S.SharedBlock.write_end(self.block.cmd_seq)

    def command_voltages(self) -> dict[str, float]:
        cmd = np.empty_like(self.block.cmd)
        S.SharedBlock.read(self.block.cmd_seq, self.block.cmd, cmd)
        return {j: float(cmd[a, S.C_VOLT]) for j, a in self.joint_index.items()}

    def neutral(self, joints=None, source: float = S.SRC_REST) -> None:
        names = self.spec.joint_names if joints is None else joints
        self.set_voltages({j: 0.0 for j in names}, source)

    def set_estop(self, on: bool) -> None:
        """E-STOP: every valve neutral until released; the commands are also zeroed."""
        self.block.estop[0] = 1.0 if on else 0.0
        if on:
            self.write_commands({a: 0.0 for a in range(len(self.spec.joints))}, S.SRC_REST)

    @property
    def estopped(self) -> bool:
        return bool(self.block.estop[0])

    # ---- cFP channel view ---------------------------------------------------------------------
    def channel_value(self, ch, snap=None, cmd=None) -> float | None:
        a = self.joint_index[ch.joint]
        if ch.role == "potentiometer":
            snap = self.block.snapshot() if snap is None else snap
            return float(snap_act(self, snap)[a, S.A_SENS_V])
        u = (self.command_voltages() if cmd is None else cmd)[ch.joint]
        return max(u, 0.0) if ch.role == "amplifier_a" else max(-u, 0.0)

    def write_channel(self, module: str, channel: str, value: float) -> dict:
        try:
            ch = self.channels.get(module, channel)
        except KeyError as exc:
            raise ServiceError(str(exc.args[0]), 404) from None
        if ch.direction == "input":
            raise ServiceError(f"{ch.name} is an analog input (potentiometer of {ch.joint}); it cannot be written")
        lo, hi = self.spec.joint(ch.joint).command_range
        top = hi if ch.role == "amplifier_a" else -lo
        if not (np.isfinite(value) and 0.0 <= value <= top):
            raise ServiceError(f"{ch.name}: {value} V is outside the amplifier input range [0, {top:g}] V")
        u = self.command_voltages()[ch.joint]
        a_val, b_val = max(u, 0.0), max(-u, 0.0)
        if ch.role == "amplifier_a":
            a_val = value
        else:
            b_val = value
        self.set_voltages({ch.joint: float(np.clip(a_val - b_val, lo, hi))})
        return {"module": module, "channel": channel, "joint": ch.joint, "value": value}

    # ---- state --------------------------------------------------------------------------------
    def lateness_percentiles(self) -> dict:
        now = time.monotonic()
        if now - self._pct_cache[0] < 0.1:
            return self._pct_cache[1]
        n = int(self.block.stats[-1])
        ring = self.block.ring[: min(n, self.block.ring.shape[0])]
        if ring.size:
            p = np.percentile(ring, [50, 99, 99.9]) * 1e6
            res = {"p50": float(p[0]), "p99": float(p[1]), "p999": float(p[2]), "max": float(ring.max() * 1e6),
                   "window_ticks": int(ring.size)}
        else:
            res = {"p50": None, "p99": None, "p999": None, "max": None, "window_ticks": 0}
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
        snap = self.block.snapshot()
        act = snap_act(self, snap)
        n = self.layout.n_dof
        q = snap[S.S_HDR:S.S_HDR + n]
        qd = snap[S.S_HDR + n:S.S_HDR + 2 * n]
        tree = self.spec.tree
        joints = {}
        for a, js in enumerate(self.spec.joints):
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
            "robot": self.spec.name,
            "time": float(snap[S.S_TIME]),
            "tick": int(snap[S.S_TICK]),
            "mode": S.MODES[int(snap[S.S_MODE])],
            "estop": bool(snap[S.S_ESTOP]),
            "supply_pressure": float(snap[S.S_P_SUPPLY]),
            "joints": joints,
            "pose": {name: float(q[i]) for i, name in enumerate(tree.dof_names)},
            "loop": self.loop_stats(),
            "faults": list(self.faults.values()),
        }

    def health(self) -> dict:
        alive = self.engine.process.is_alive() and bool(self.block.state[S.S_ALIVE])
        rt = bool(self.block.state[S.S_RTPRIO])
        return {
            "status": "ok" if alive else "engine_down",
            "robot": self.spec.name,
            "mode": S.MODES[int(self.block.state[S.S_MODE])],
            "rate_hz": self.cfg.rate_hz,
            "tick": int(self.block.state[S.S_TICK]),
            "uptime_s": time.time() - self.started,
            "engine_alive": alive,
            "realtime_priority": rt,
            "realtime_note": self.engine.info.get("priority_note", ""),
            "estop": self.estopped,
            "can": self.bridge.describe() if self.bridge else None,
            "auth_required": bool(self.cfg.token),
        }

    # ---- control -------------------------------------------------------------------------------
    def _engine(self, op: str, *args, timeout: float = 60.0):
        try:
            return self.engine.request(op, *args, timeout=timeout)
        except EngineError as exc:
            raise ServiceError(str(exc), 409 if op in ("step",) else 422) from None
        except (RuntimeError, TimeoutError) as exc:
            raise ServiceError(str(exc), 503) from None

    def set_mode(self, mode: str) -> dict:
        if mode not in S.MODES:
            raise ServiceError(f"unknown mode {mode!r}; modes: {', '.join(S.MODES)}")
        return self._engine("mode", mode)

    def step(self, ticks: int) -> dict:
        if S.MODES[int(self.block.state[S.S_MODE])] != "lockstep":
            raise ServiceError("step needs lockstep mode; PUT /api/v1/mode {\"mode\": \"lockstep\"} first", 409)
        return self._engine("step", int(ticks), timeout=600.0)

    def reset(self, seed: int | None) -> dict:
        """Initial pose at time 0 with every valve neutral (commands from before must not act on the
        first tick after a reset; lockstep runs are then reproducible)."""
        if self.recorder.current is not None:
            self.recorder.stop()  # a recording must not run across a reset of sim time
        out = self._engine("reset", seed)
        self.write_commands({a: 0.0 for a in range(len(self.spec.joints))}, S.SRC_NONE)
        return out

    # ---- parameters and effects ------------------------------------------------------------------
    def parameters(self) -> dict:
        return {"robot": self.spec.name, "values": self.spec.parameters(),
                "effects": [e.to_dict() for e in self.spec.effects]}

    def patch_parameters(self, values: dict) -> dict:
        with self._param_lock:
            trial = self.spec.copy()
            try:
                for path, v in values.items():
                    trial.set(path, v)
            except SpecError as exc:
                raise ServiceError(str(exc)) from None
            applied = self._engine("set_parameters", values)
            self.spec = trial
            return applied

    def effects(self) -> dict:
        return {"catalog": catalog(), "enabled": [e.to_dict() for e in self.spec.effects]}

    def enable_effect(self, name: str, joint: str | None, params: dict) -> dict:
        with self._param_lock:
            trial = self.spec.copy()
            try:
                trial.enable_effect(name, joint, **params)
            except SpecError as exc:
                raise ServiceError(str(exc)) from None
            out = self._engine("enable_effect", name, joint, params)
            self.spec = trial
            return out

    def disable_effect(self, name: str, joint: str | None) -> dict:
        with self._param_lock:
            trial = self.spec.copy()
            if not trial.disable_effect(name, joint):
                raise ServiceError(f"effect {name} on {joint} is not enabled", 404)
            out = self._engine("disable_effect", name, joint)
            self.spec = trial
            return out

    # ---- faults ---------------------------------------------------------------------------------
    def inject_fault(self, kind: str, joint: str | None, params: dict) -> dict:
        key = f"{kind}:{joint or 'supply'}"
        if kind != "supply_sag":
            if joint not in self.joint_index:
                raise ServiceError(f"fault {kind}: unknown joint {joint!r}; joints: {', '.join(self.spec.joint_names)}")
            if kind.startswith("sensor_") and not self.spec.joint(joint).sensed:
                raise ServiceError(f"fault {kind}: joint {joint} has no sensor")
        elif joint is not None:
            raise ServiceError("supply_sag acts on the whole supply; do not give a joint")
        self._engine("set_fault", joint, kind, params)
        fault = {"id": key, "kind": kind, "joint": joint, "params": params, "since": self.state_time()}
        self.faults[key] = fault
        return fault

    def clear_fault(self, fid: str) -> dict:
        fault = self.faults.get(fid)
        if fault is None:
            raise ServiceError(f"no active fault {fid!r}", 404)
        self._engine("clear_fault", fault["joint"], fault["kind"])
        del self.faults[fid]
        return fault

    def clear_faults(self) -> None:
        self._engine("clear_faults")
        self.faults.clear()

    def state_time(self) -> float:
        return float(self.block.state[S.S_TIME])


def snap_act(service: HilService, snap: np.ndarray) -> np.ndarray:
    n = service.layout.n_dof
    return snap[S.S_HDR + 2 * n:].reshape(service.layout.n_act, S.A_N)


class Metrics:
    """Request and frame counters for the Prometheus endpoint (thread-safe enough: GIL increments)."""

    def __init__(self):
        self.http: dict[tuple[str, str, int], int] = {}
        self._lock = threading.Lock()

    def count_http(self, method: str, route: str, status: int) -> None:
        key = (method, route, status)
        with self._lock:
            self.http[key] = self.http.get(key, 0) + 1
