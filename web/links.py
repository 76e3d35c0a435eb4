"""Plant links: where the viewer gets the plant state from and where it sends commands to.

Two kinds, one interface (what :class:`web.viewer.Viewer` and :class:`web.panel.OperatorPanel` use):

* :class:`LocalLink` talks to an in-process :class:`hil_server.service.HilService` (``hydrohil serve``):
  the state is a copy out of the engine's shared memory (~25 us), commands are written straight into
  the command area with source ``viewer``.
* :class:`RemoteLink` attaches to a running server over REST: it keeps the latest state document
  from ``WebSocket /api/v1/stream`` (a reader thread that reconnects on its own) and sends commands
  with ``PUT /api/v1/commands`` from a sender thread that coalesces slider drags (latest value wins),
  so a slow network never blocks the GUI.

Interface: ``spec`` (sim_core RobotSpec), ``latest()`` -> state document or None, ``status()`` ->
connection dict, ``set_voltages({joint: V})``, ``neutral([joints])``, ``set_estop(bool)``,
``can_command``, ``errors`` (callbacks ``f(message)`` for refused commands), ``close()``.
"""

from __future__ import annotations

import json
import logging
import threading
import time
import urllib.error
import urllib.parse
import urllib.request

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

    @property
    def spec(self):
        return self.service.spec  # follows parameter patches (cylinder mounts, command ranges)

    @property
    def robot(self) -> str:
        return self.service.spec.name

    def latest(self) -> dict | None:
        return self.service.state()

    def status(self) -> dict:
        try:
            alive = bool(self.service.health()["engine_alive"])
        except Exception:  # noqa: BLE001 - a closing service
            alive = False
        return {"kind": self.kind, "where": "in-process", "connected": alive, "age_s": 0.0,
                "detail": "engine running" if alive else "engine down", "reconnects": 0}

    def set_voltages(self, voltages: dict[str, float]) -> None:
        from hil_server.service import ServiceError

        try:
            self.service.set_voltages(voltages, self._src)
        except ServiceError as exc:
            raise LinkError(str(exc)) from None

    def neutral(self, joints=None) -> None:
        self.service.neutral(joints, self._src)

    def set_estop(self, on: bool) -> None:
        self.service.set_estop(bool(on))

    def close(self) -> None:
        pass


class RemoteLink:
    """A HydroHIL server reached over its REST API (``hydrohil view --url``)."""

    kind = "remote"

    def __init__(self, url: str, token: str | None = None, *, rate_hz: float = 60.0, timeout: float = 5.0):
        from sim_core.model.spec import SpecError, load_robot

        u = urllib.parse.urlsplit(url if "://" in url else f"http://{url}")
        if u.scheme not in ("http", "https"):
            raise LinkError(f"--url {url!r}: use http://host:port (the server's REST address)")
        self.base = f"{u.scheme}://{u.netloc}{u.path.rstrip('/')}"
        ws_scheme = "wss" if u.scheme == "https" else "ws"
        rate = min(max(rate_hz, 1.0), 250.0)
        self.ws_url = f"{ws_scheme}://{u.netloc}{u.path.rstrip('/')}/api/v1/stream?rate={rate:g}"
        self.token = token
        self.timeout = timeout
        self.errors: list = []
        health = self._request("GET", "/api/v1/health")
        self.robot = health["robot"]
        self.auth_required = bool(health.get("auth_required"))
        self.can_command = not self.auth_required or bool(token)
        try:
            self.spec = load_robot(self.robot)
        except SpecError as exc:
            raise LinkError(f"server runs robot {self.robot!r}, which this installation does not know: {exc}") from None
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
        self._reader = threading.Thread(target=self._read_loop, name="hydrohil-view-stream", daemon=True)
        self._sender = threading.Thread(target=self._send_loop, name="hydrohil-view-commands", daemon=True)
        self._reader.start()
        self._sender.start()

    # ---- HTTP --------------------------------------------------------------------------------
    def _request(self, method: str, path: str, body: dict | None = None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method)
        req.add_header("Accept", "application/json")
        if data is not None:
            req.add_header("Content-Type", "application/json")
        if self.token and method != "GET":
            req.add_header("Authorization", f"Bearer {self.token}")
        try:
            with urllib.request.urlopen(req, timeout=self.timeout) as resp:
                return json.loads(resp.read() or b"null")
        except urllib.error.HTTPError as exc:
            try:
                detail = json.loads(exc.read()).get("detail", exc.reason)
            except Exception:  # noqa: BLE001
                detail = exc.reason
            raise LinkError(f"{method} {path}: HTTP {exc.code}: {detail}") from None
        except (urllib.error.URLError, OSError, ValueError) as exc:
            reason = getattr(exc, "reason", exc)
            raise LinkError(f"cannot reach {self.base} ({method} {path}): {reason}") from None

    def _mirror_parameters(self) -> None:
        """Take the server's cylinder mounts and command ranges (a --params file may change them)."""
        try:
            values = self._request("GET", "/api/v1/parameters")["values"]
        except (LinkError, KeyError, TypeError) as exc:
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

    # ---- stream --------------------------------------------------------------------------------
    def _read_loop(self) -> None:
        from websockets.sync.client import connect

        backoff = 0.2
        while not self._stop.is_set():
            try:
                with connect(self.ws_url, open_timeout=self.timeout, close_timeout=1.0, max_size=None) as ws:
                    self._ws = ws
                    backoff = 0.2
                    while not self._stop.is_set():
                        doc = json.loads(ws.recv(timeout=max(self.timeout, 2.0)))
                        with self._lock:
                            self._state = doc
                            self._rx_time = time.monotonic()
                            self._rx_count += 1
                            self._connected = True
                            self._error = ""
            except Exception as exc:  # noqa: BLE001 - any failure: mark down, retry
                if self._stop.is_set():
                    break
                with self._lock:
                    if self._connected:
                        self._reconnects += 1
                    self._connected = False
                    self._error = f"{type(exc).__name__}: {exc}"[:200]
                self._stop.wait(backoff)
                backoff = min(backoff * 2.0, 3.0)
            finally:
                self._ws = None

    def latest(self) -> dict | None:
        with self._lock:
            return self._state

    def status(self) -> dict:
        with self._lock:
            age = time.monotonic() - self._rx_time if self._rx_time else None
            connected = self._connected and age is not None and age < max(self.timeout, 2.0)
            detail = "streaming" if connected else (self._error or "connecting")
            return {"kind": self.kind, "where": self.base, "connected": connected, "age_s": age,
                    "detail": detail, "reconnects": self._reconnects, "messages": self._rx_count}

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
                self._request("PUT", "/api/v1/commands", {"voltages": batch, "source": "viewer"})
            except LinkError as exc:
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
        self._request("PUT", "/api/v1/estop", {"engaged": bool(on)})

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        ws = self._ws
        if ws is not None:
            try:
                ws.close()
            except Exception:  # noqa: BLE001
                pass
        for t in (self._reader, self._sender):
            t.join(timeout=3.0)
