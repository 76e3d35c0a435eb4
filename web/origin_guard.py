"""The viewer's WebSocket refuses foreign Origins.

Any web page the operator has open could otherwise open ``ws://127.0.0.1:8080`` in the background and
move sliders (cross-site WebSocket hijacking), and a DNS-rebinding page could pose as this host. A
browser connection is accepted only when its ``Origin`` is the page's own address (Origin host:port
equals the ``Host`` header) and, on a loopback bind, that address is a loopback name. Clients that
send no Origin are not browsers and are let through (the attack needs a browser).

viser has no hook for the WebSocket handshake, so the check runs as the first thing after it: a
connect callback on viser's WebSocket server (``_websock_server``, whose connect callbacks all run
before the connection's messages are read) that looks at the handshake request (``_live_connections``)
and closes a foreign connection with code 1008 before it can send anything. viser accepts connections
from inside its constructor, before the guard can be installed, so installing it also checks every
connection already open (on viser's event loop, after the callback is in place, so none slips between
the two). The panel also refuses commands from any client this guard has not accepted (deny by
default). These attributes are viser internals: if they are missing the viewer does not start rather
than run unguarded.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import urllib.parse

log = logging.getLogger("hydrohil.web")

LOOPBACK_NAMES = {"127.0.0.1", "localhost", "::1", "[::1]"}
OPEN_CHECK_TIMEOUT_S = 10.0     # the check of already open connections waits this long for viser's loop


def _host_port(netloc: str, default_port: int) -> tuple[str, int]:
    u = urllib.parse.urlsplit("//" + netloc)
    host = (u.hostname or "").lower()
    try:
        port = u.port or default_port
    except ValueError:
        port = -1
    return host, port


def origin_allowed(origin: str | None, host_header: str | None, bind_is_loopback: bool) -> bool:
    if origin is None:
        return True
    u = urllib.parse.urlsplit(origin)
    if u.scheme not in ("http", "https") or not u.netloc or not host_header:
        return False
    default = 443 if u.scheme == "https" else 80
    o_host, o_port = _host_port(u.netloc, default)
    h_host, h_port = _host_port(host_header, default)
    if (o_host, o_port) != (h_host, h_port):
        return False
    if bind_is_loopback:
        return o_host in LOOPBACK_NAMES or o_host.startswith("127.")
    return True


class OriginGuard:
    def __init__(self, viser_server, bind_is_loopback: bool):
        self.bind_is_loopback = bind_is_loopback
        self.accepted: set[int] = set()
        self.refused = 0
        self._checked: set[int] = set()
        self._closing: set[asyncio.Task] = set()      # referenced until done (the loop keeps weak ones)
        self._lock = threading.Lock()
        try:
            ws_server = viser_server._websock_server
            self._connections = ws_server._live_connections
            loop = ws_server._background_event_loop
            ws_server.on_client_connect(self._on_connect)
            ws_server.on_client_disconnect(self._on_disconnect)
        except AttributeError as exc:
            raise RuntimeError(f"this viser version offers no way to check WebSocket Origins ({exc}); "
                               "the viewer does not start unguarded") from None
        if loop is not None:
            asyncio.run_coroutine_threadsafe(self._check_open(), loop).result(timeout=OPEN_CHECK_TIMEOUT_S)

    def allowed(self, client_id) -> bool:
        with self._lock:
            return client_id in self.accepted

    def _admit(self, client_id, ws) -> bool | None:
        """Decide once per connection: True accepted, False refused, None already decided."""
        request = getattr(ws, "request", None)
        headers = request.headers if request is not None else {}
        origin, host = headers.get("Origin"), headers.get("Host")
        ok = ws is not None and origin_allowed(origin, host, self.bind_is_loopback)
        with self._lock:
            if client_id in self._checked:
                return None
            self._checked.add(client_id)
            if ok:
                self.accepted.add(client_id)
            else:
                self.refused += 1
        if not ok:
            log.warning("viewer: refused a WebSocket from Origin %r (page served as %r)", origin, host)
        return ok

    async def _on_connect(self, conn) -> None:
        ws = self._connections.get(conn.client_id)
        if self._admit(conn.client_id, ws) is False and ws is not None:
            await ws.close(1008, "foreign Origin")

    async def _check_open(self) -> None:
        """Connections opened before the guard was installed: the same check, the close not awaited
        (a client that never answers the close must not hold up the viewer's start)."""
        for client_id, ws in tuple(self._connections.items()):
            if self._admit(client_id, ws) is False:
                task = asyncio.get_running_loop().create_task(ws.close(1008, "foreign Origin"))
                self._closing.add(task)
                task.add_done_callback(self._closing.discard)

    async def _on_disconnect(self, conn) -> None:
        with self._lock:
            self.accepted.discard(conn.client_id)
            self._checked.discard(conn.client_id)
