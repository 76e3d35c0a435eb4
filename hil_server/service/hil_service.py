"""HilService: the composition root of the emulator. It builds the parts and wires them together;
each part owns one responsibility and REST routers, the CAN bridge and viewers talk to the parts:

* ``supervisor``  the engine process: start, watch, restart (:mod:`.supervisor`)
* ``params``      the parameter mirror (:mod:`.parameters`)
* ``commands``    valve commands and E-STOP (:mod:`.commands`)
* ``cfp``         the CompactFieldPoint module/channel view (:mod:`.cfp`)
* ``documents``   state documents and loop statistics (:mod:`.documents`)
* ``health``      the health document (:mod:`.health`)
* ``control``     mode, lockstep steps, reset (:mod:`.control`)
* ``faults``      injected faults and the latched ``diverged`` fault (:mod:`.faults`)
* ``recorder``    recordings (:mod:`hil_server.recorder`)
* ``metrics``     counters for ``/metrics`` (:mod:`.metrics`)
* ``bridge``      CAN (:mod:`hil_server.can.bridge`), ``plugins`` viewers

Construct it on a thread that lives as long as the service (the main thread): the engine process
dies with the thread that started it (PR_SET_PDEATHSIG); restarts happen on the supervisor's thread.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from importlib.metadata import entry_points
from pathlib import Path

from sim_core.model.spec import RobotSpec, load_robot
from sim_core.params_file import ParamsFileError, apply_params_file

from ..channels import ChannelMap
from ..engine import shared as S
from ..engine.atomics import SharedMemoryUnsupported, check_platform
from ..engine.process import EngineConfig
from ..recorder import Recorder
from .cfp import CfpView
from .commands import CommandTable
from .config import ServiceConfig, ServiceError
from .control import PlantControl
from .documents import StateDocuments
from .faults import FaultTable
from .health import HealthReport
from .metrics import Metrics
from .parameters import ParameterMirror
from .supervisor import EngineSupervisor

log = logging.getLogger("hydrohil.service")


class HilService:
    def __init__(self, cfg: ServiceConfig):
        if not 1.0 <= cfg.rate_hz <= 20000.0:
            raise ServiceError(f"--rate {cfg.rate_hz}: must be between 1 and 20000 Hz")
        if cfg.mode not in S.MODES:
            raise ServiceError(f"--mode {cfg.mode!r}: one of {', '.join(S.MODES)}")
        if cfg.engine_restart not in ("auto", "never"):
            raise ServiceError(f"--engine-restart {cfg.engine_restart!r}: auto or never")
        if cfg.can:
            from ..can.transports import check_spec

            try:
                check_spec(cfg.can)
            except ValueError as exc:
                raise ServiceError(f"--can {cfg.can}: {exc}") from None
        try:
            check_platform()
        except SharedMemoryUnsupported as exc:
            raise ServiceError(f"cannot run on this host: {exc}") from None
        self.cfg = cfg
        spec: RobotSpec = load_robot(cfg.robot)
        if cfg.params:
            try:
                apply_params_file(spec, cfg.params)
            except ParamsFileError as exc:
                raise ServiceError(str(exc)) from None
        self.layout = S.Layout(spec.tree.n, len(spec.joints), len(spec.sensed_joints),
                               max(1000, int(cfg.recording_ring_s * cfg.rate_hz)))
        self.block = S.SharedBlock(self.layout)
        self.metrics = Metrics()
        self.supervisor = EngineSupervisor(
            lambda: self.params.spec,
            EngineConfig(rate_hz=cfg.rate_hz, mode=cfg.mode, watchdog_ms=cfg.watchdog_ms, seed=cfg.seed,
                         realtime_priority=cfg.realtime_priority, cpu=cfg.engine_cpu),
            self.layout, self.block, restart=cfg.engine_restart, max_per_min=cfg.max_restarts_per_min,
            stall_s=cfg.stall_ms / 1000.0, before_start=lambda: self.commands.zero_all(S.SRC_NONE))
        self.params = ParameterMirror(spec, self.supervisor)
        self.commands = CommandTable(self.block, self.params, self.supervisor)
        self.faults = FaultTable(self.params, self.supervisor, self.block)
        self.recorder = Recorder(self.block, spec, Path(cfg.recordings_dir), self.supervisor)
        self.documents = StateDocuments(self.block, self.params, self.faults, self.supervisor)
        self.cfp = CfpView(ChannelMap(spec), self.commands, self.documents)
        self.control = PlantControl(self.block, self.supervisor, self.commands, self.recorder, self.faults)
        self.health = HealthReport(self)
        self.bridge = None
        self._can_loop: asyncio.AbstractEventLoop | None = None
        self._can_thread: threading.Thread | None = None
        self.plugins: list = []
        self._closed = False
        sup = self.supervisor
        sup.on_down += [self._engine_down]
        sup.on_up += [self._engine_up]
        sup.on_event += [self._engine_event]
        try:
            sup.start()
        except BaseException:
            self.block.close()
            raise

    @property
    def spec(self) -> RobotSpec:
        """The parameter mirror's current spec (follows patches)."""
        return self.params.spec

    # ---- supervision events (supervisor thread) ---------------------------------------------------
    def _engine_down(self, kind: str, reason: str) -> None:
        if self.bridge is not None:
            self.bridge.engine_down(kind, reason)
        self.recorder.abort(f"engine {kind}: {reason}")

    def _engine_up(self, restarts: int) -> None:
        self.faults.forget_injected()
        if self.bridge is not None:
            self.bridge.engine_up(restarts)

    def _engine_event(self, name: str, payload) -> None:
        if name == "diverged":
            fault = self.faults.latch_diverged(payload)
            if self.bridge is not None:
                self.bridge.plant_diverged(fault)

    # ---- lifecycle -------------------------------------------------------------------------------
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
        from ..can.bridge import CanBridge

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
            self.supervisor.close()
            self.block.close()
