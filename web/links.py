"""Plant links: where the viewer gets the plant state from and where it sends commands to.

Two kinds, one interface (what :class:`web.viewer.Viewer` and :class:`web.panel.OperatorPanel` use):

* :class:`LocalLink` talks to an in-process :class:`hil_server.service.HilService` (``hydrohil serve``):
  the state is a copy out of the engine's shared memory (~25 us), commands are written straight into
  the command table with source ``viewer``.
* :class:`RemoteLink` attaches to a running server through :class:`hil_server.client.HilClient`: it
  keeps the latest state document from ``WebSocket /api/v1/stream`` (a reader thread that reconnects
  on its own; a server with a token streams only to a link that has it, so a link without the token
  polls the public ``GET /api/v1/state`` instead, read-only) and sends commands with
  ``PUT /api/v1/commands`` from a sender thread that coalesces slider drags (latest value wins), so a
  slow network never blocks the GUI.

Interface: ``spec`` (sim_core RobotSpec), ``latest()`` -> state document or None (None while the
engine is down), ``status()`` -> connection dict (with ``engine`` and ``warnings``),
``set_voltages({joint: V})``, ``neutral([joints])``, ``set_estop(bool)``, ``can_command``, ``token``
(what a browser must enter to command through a non-loopback viewer), ``errors`` (callbacks
``f(message)`` for refused commands), ``close()``.
"""

from __future__ import annotations

import json
import logging
import threading
import time

from hil_server.client import ClientError, HilClient

log = logging.getLogger("hydrohil.web")


class LinkError(RuntimeError):
    """A command or connection the link could not complete (the message says why)."""


class LocalLink:
    """The in-process service (``hydrohil serve`` loads the viewer as a plugin)."""

    kind = "local"

    def __init__(self, service):
        from hil_server.engine.shared import SRC_VIEWER

        self.service = service
        self._src = SRC_VIEWER
        self.errors: list = []
        self.can_command = True
        self.token = service.cfg.token

    @property
    def spec(self):
        return self.service.params.spec  # follows parameter patches (cylinder mounts, command ranges)

    @property
    def robot(self) -> str:
        return self.spec.name

    def latest(self) -> dict | None:
        from hil_server.service import ServiceError

        try:
            return self.service.documents.state()
        except ServiceError:
            return None   # engine down: nothing to show as if it were the plant

    def status(self) -> dict:
        try:
            h = self.service.health.document()
        except Exception:  # noqa: BLE001 - a closing service
            h = {"engine_alive": False, "engine": {"state": "stopped"}, "warnings": []}
        up = h["engine"]["state"] == "running"
        return {"kind": self.kind, "where": "in-process", "connected": up, "age_s": 0.0,
                "detail": "engine running" if up else (h["engine"].get("reason") or "engine down"), "reconnects": 0,
                "engine": h["engine"], "warnings": h.get("warnings", [])}

    def set_voltages(self, voltages: dict[str, float]) -> None:
        from hil_server.service import ServiceError

        try:
            self.service.commands.set(voltages, self._src)
        except ServiceError as exc:
            raise LinkError(str(exc)) from None

    def neutral(self, joints=None) -> None:
        self.set_voltages({j: 0.0 for j in (self.spec.joint_names if joints is None else joints)})

    def set_estop(self, on: bool) -> None:
        self.service.commands.set_estop(bool(on))

    def close(self) -> None:
        pass


class RemoteLink:
    """A HydroHIL server reached over its REST API (``hydrohil view --url``)."""

    kind = "remote"

    def __init__(self, url: str, token: str | None = None, *, rate_hz: float = 60.0, timeout: float = 5.0,
                 robot: str | None = None):
        from sim_core.model.spec import SpecError, load_robot

        try:
            self.client = HilClient(url, token, timeout=timeout)
            health = self.client.health()
        except ClientError as exc:
            raise LinkError(str(exc)) from None
        self.base = self.client.base
        self.rate_hz = min(max(rate_hz, 1.0), 250.0)
        self.ws_url = self.client.stream_url(self.rate_hz)
        self.token = token
        self.timeout = timeout
        self.errors: list = []
        self.robot = health["robot"]
        self.auth_required = bool(health.get("auth_required"))
        self.can_command = not self.auth_required or bool(token)
        self.polling = self.auth_required and not token    # the stream needs the token; GET /state does not
        self._health = health
        try:
            self.spec = load_robot(robot or self.robot)
        except SpecError as exc:
            raise LinkError(f"server runs robot {self.robot!r}, which this installation does not know: {exc} "
                            f"(a rig of your own: give its directory with --robot)") from None
        if self.spec.name != self.robot:
            raise LinkError(f"--robot {robot}: is robot {self.spec.name!r}, but the server runs {self.robot!r}")
        self._mirror_parameters()
        self._lock = threading.Lock()
        self._state: dict | None = None
        self._rx_time = 0.0
        self._rx_count = 0
        self._connected = False
        self._reconnects = 0
        self._error = ""
        self._pending: dict[str, float] = {}
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._ws = None
        self._reader = threading.Thread(target=self._poll_loop if self.polling else self._read_loop,
                                        name="hydrohil-view-stream", daemon=True)
        self._sender = threading.Thread(target=self._send_loop, name="hydrohil-view-commands", daemon=True)
        self._health_thread = threading.Thread(target=self._health_loop, name="hydrohil-view-health", daemon=True)
        self._reader.start()
        self._sender.start()
        self._health_thread.start()

    def _mirror_parameters(self) -> None:
        """Take the server's cylinder mounts and command ranges (a --params file may change them)."""
        try:
            values = self.client.parameters()["values"]
        except (ClientError, KeyError, TypeError) as exc:
            log.warning("viewer: could not read the server's parameters (%s); using the built-in spec", exc)
            return
        for path, value in values.items():
            parts = path.split(".")
            if len(parts) == 4 and parts[0] == "joints" and (parts[2] == "cylinder" or parts[3] == "command_range"):
                try:
                    if self.spec.get(path) != value:
                        self.spec.set(path, value)
                except Exception as exc:  # noqa: BLE001 - keep the local value, say so
                    log.warning("viewer: parameter %s from the server not applied: %s", path, exc)

    # ---- state ---------------------------------------------------------------------------------
    def _received(self, doc: dict) -> None:
        with self._lock:
            self._state = doc
            self._rx_time = time.monotonic()
            self._rx_count += 1
            self._connected = True
            self._error = ""

    def _lost(self, exc: BaseException) -> None:
        with self._lock:
            if self._connected:
                self._reconnects += 1
            self._connected = False
            self._state = None
            self._error = f"{type(exc).__name__}: {exc}"[:200]

    def _read_loop(self) -> None:
        from websockets.sync.client import connect

        backoff = 0.2
        while not self._stop.is_set():
            try:
                with connect(self.ws_url, open_timeout=self.timeout, close_timeout=1.0, max_size=None,
                             additional_headers=self.client.headers()) as ws:
                    self._ws = ws
                    backoff = 0.2
                    while not self._stop.is_set():
                        self._received(json.loads(ws.recv(timeout=max(self.timeout, 2.0))))
            except Exception as exc:  # noqa: BLE001 - any failure (also 1013 engine down): mark down, retry
                if self._stop.is_set():
                    break
                self._lost(exc)
                self._stop.wait(backoff)
                backoff = min(backoff * 2.0, 3.0)
            finally:
                self._ws = None

    def _poll_loop(self) -> None:
        period = 1.0 / min(self.rate_hz, 20.0)
        while not self._stop.is_set():
            t0 = time.monotonic()
            try:
                self._received(self.client.state(timeout=self.timeout))
            except ClientError as exc:
                self._lost(exc)
            self._stop.wait(max(0.0, period - (time.monotonic() - t0)))

    def _health_loop(self) -> None:
        while not self._stop.wait(1.0):
            try:
                h = self.client.health(timeout=self.timeout)
            except ClientError:
                continue
            with self._lock:
                self._health = h

    def latest(self) -> dict | None:
        with self._lock:
            return self._state

    def status(self) -> dict:
        with self._lock:
            age = time.monotonic() - self._rx_time if self._rx_time else None
            connected = self._connected and age is not None and age < max(self.timeout, 2.0)
            detail = ("polling (read-only: no token)" if self.polling else "streaming") if connected \
                else (self._error or "connecting")
            return {"kind": self.kind, "where": self.base, "connected": connected, "age_s": age,
                    "detail": detail, "reconnects": self._reconnects, "messages": self._rx_count,
                    "engine": self._health.get("engine", {}), "warnings": list(self._health.get("warnings", []))}

    # ---- commands --------------------------------------------------------------------------------
    def _report(self, msg: str) -> None:
        log.warning("viewer: %s", msg)
        for cb in list(self.errors):
            try:
                cb(msg)
            except Exception:  # noqa: BLE001
                pass

    def _send_loop(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(0.5)
            self._wake.clear()
            with self._lock:
                batch, self._pending = self._pending, {}
            if not batch:
                continue
            try:
                self.client.set_voltages(batch, source="viewer")
            except ClientError as exc:
                self._report(str(exc))

    def set_voltages(self, voltages: dict[str, float]) -> None:
        if not self.can_command:
            raise LinkError("this server needs a token for commands (hydrohil view --token T)")
        for j in voltages:
            self.spec.joint(j)  # unknown joint: SpecError (a ValueError) right here
        with self._lock:
            self._pending.update({j: float(v) for j, v in voltages.items()})
        self._wake.set()

    def neutral(self, joints=None) -> None:
        self.set_voltages({j: 0.0 for j in (self.spec.joint_names if joints is None else joints)})

    def set_estop(self, on: bool) -> None:
        with self._lock:
            if on:
                self._pending.clear()  # nothing queued before the stop may follow it
        try:
            self.client.estop(on)
        except ClientError as exc:
            raise LinkError(str(exc)) from None

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        ws = self._ws
        if ws is not None:
            try:
                ws.close()
            except Exception:  # noqa: BLE001
                pass
        for t in (self._reader, self._sender, self._health_thread):
            t.join(timeout=3.0)
