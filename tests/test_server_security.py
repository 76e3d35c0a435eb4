"""Secure by default, on real processes: an unprotected bind beyond loopback is refused (or, with
--insecure, warned about in the log, /health, /metrics and the viewer); tokens from the environment
or a file; every protected endpoint refuses a missing or a wrong token, the state stream and
recording downloads included; an exposed socketcand server is warned about; the viewer's WebSocket
refuses foreign Origins."""

import asyncio
import json
import time

import httpx
import pytest
import websockets

from hil_server.security import is_loopback, resolve_token

from server_helpers import ServerProcess, free_port
from web_helpers import ViserProbe, get_or_none, wait_for

pytestmark = pytest.mark.realtime

TOKEN = "t0ken-for-tests"

PROTECTED = [
    ("put", "/api/v1/commands", {"voltages": {"j2": 1.0}}),
    ("post", "/api/v1/commands/neutral", None),
    ("put", "/api/v1/estop", {"engaged": True}),
    ("put", "/api/v1/cfp/cFP1/AO2", {"value": 1.0}),
    ("put", "/api/v1/mode", {"mode": "paused"}),
    ("post", "/api/v1/step", {"ticks": 1}),
    ("post", "/api/v1/reset", {}),
    ("patch", "/api/v1/parameters", {"values": {"supply.pressure": 1e7}}),
    ("put", "/api/v1/effects/deadband", {"joint": "j2", "params": {"width": 1.0}}),
    ("delete", "/api/v1/effects/deadband", None),
    ("post", "/api/v1/faults", {"kind": "supply_sag", "factor": 0.5}),
    ("delete", "/api/v1/faults", None),
    ("delete", "/api/v1/faults/supply_sag:supply", None),
    ("post", "/api/v1/recordings", {}),
    ("post", "/api/v1/recordings/stop", None),
]


def test_loopback_addresses_are_recognised():
    assert is_loopback("127.0.0.1") and is_loopback("localhost") and is_loopback("::1") and is_loopback("127.3.2.1")
    assert not is_loopback("0.0.0.0") and not is_loopback("::") and not is_loopback("192.0.2.7")


def test_a_bind_beyond_loopback_without_a_token_is_refused(cli, tmp_path):
    proc = cli("serve", "--host", "0.0.0.0", "--port", "0", "--viewer-port", "0", "--can", "none", timeout=120)
    assert proc.returncode == 2 and "no token" in proc.stderr and "--insecure" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    empty = tmp_path / "empty"
    empty.write_text("\n")
    proc = cli("serve", "--host", "0.0.0.0", "--token-file", str(empty), "--port", "0", "--viewer-port", "0", timeout=120)
    assert proc.returncode == 2 and "is empty" in proc.stderr
    proc = cli("serve", "--token-file", str(tmp_path / "missing"), "--port", "0", "--viewer-port", "0", timeout=120)
    assert proc.returncode == 2 and "--token-file" in proc.stderr and str(tmp_path / "missing") in proc.stderr


def test_token_sources_and_their_warnings(tmp_path):
    f = tmp_path / "token"
    f.write_text("from-file\n")
    f.chmod(0o600)
    assert resolve_token("from-cli", str(f), env={"HYDROHIL_TOKEN": "from-env"}) == ("from-file", [])
    assert resolve_token("from-cli", None, env={"HYDROHIL_TOKEN": "from-env"}) == ("from-env", [])
    token, warnings = resolve_token("from-cli", None, env={})
    assert token == "from-cli" and "visible" in warnings[0] and "ps" in warnings[0]
    f.chmod(0o644)
    assert "readable by other users" in resolve_token(None, str(f), env={})[1][0]


def test_insecure_is_loud_in_the_log_health_metrics_and_viewer(tmp_path):
    vport = free_port()
    srv = ServerProcess("--host", "0.0.0.0", "--insecure", robot="hydrolek", viewer_port=vport, tmp_path=tmp_path)
    try:
        with httpx.Client(base_url=srv.url, timeout=30) as c:
            h = c.get("/api/v1/health").json()
            assert h["insecure"] and any(w.startswith("INSECURE") for w in h["warnings"])
            assert "hydrohil_insecure 1" in c.get("/metrics").text
        assert "WARNING INSECURE" in srv.log_text()
        wait_for(lambda: get_or_none(f"http://127.0.0.1:{vport}/"), 60, "the viewer")
        probe = ViserProbe(vport)
        try:
            wait_for(lambda: any("INSECURE" in str(m.get("updates", {}).get("content", "")) or
                                 "INSECURE" in str(m.get("props", {}).get("content", ""))
                                 for _, m in probe.messages), 30, "the viewer's insecure warning")
        finally:
            probe.close()
    finally:
        srv.stop()


def test_every_protected_endpoint_refuses_a_missing_or_wrong_token(tmp_path):
    cport = free_port()
    srv = ServerProcess("--host", "0.0.0.0", "--token", "ignored-because-env-wins", robot="hydrolek",
                        can=f"socketcand:{cport}@0.0.0.0", tmp_path=tmp_path, token=TOKEN)
    try:
        with httpx.Client(base_url=srv.url, timeout=30) as anon:
            h = anon.get("/api/v1/health").json()
            assert h["auth_required"] and not h["insecure"]
            assert any("socketcand" in w and "no authentication" in w for w in h["warnings"])
            assert anon.get("/api/v1/state").status_code == 200          # reading the state stays open
            for method, path, body in PROTECTED:
                kw = {} if body is None else {"json": body}
                r = getattr(anon, method)(path, **kw)
                assert r.status_code == 401 and r.headers.get("www-authenticate") == "Bearer", path
                r = getattr(anon, method)(path, headers={"Authorization": "Bearer wrong"}, **kw)
                assert r.status_code == 403, path
            # a recording made with the token: its download needs it too
            with srv.client() as c:
                rec = c.post("/api/v1/recordings", json={"name": "secret"}).json()
                time.sleep(0.2)
                c.post("/api/v1/recordings/stop").raise_for_status()
                assert c.get(f"/api/v1/recordings/{rec['id']}/data").status_code == 200
            data = f"/api/v1/recordings/{rec['id']}/data"
            assert anon.get(data).status_code == 401
            assert anon.get(data, headers={"Authorization": "Bearer wrong"}).status_code == 403
        # the state stream
        ws_url = srv.url.replace("http", "ws") + "/api/v1/stream?rate=20"

        async def stream(headers=None, query=""):
            async with websockets.connect(ws_url + query, additional_headers=headers or {}) as ws:
                return json.loads(await ws.recv())

        for headers, query in ((None, ""), ({"Authorization": "Bearer wrong"}, ""), (None, "&token=wrong")):
            with pytest.raises(websockets.exceptions.InvalidStatus) as err:
                asyncio.run(stream(headers, query))
            assert err.value.response.status_code == 403
        assert asyncio.run(stream({"Authorization": f"Bearer {TOKEN}"}))["robot"] == "hydrolek"
        assert asyncio.run(stream(query=f"&token={TOKEN}"))["robot"] == "hydrolek"
        log = srv.log_text()
        assert "socketcand CAN server exposed" in log
    finally:
        srv.stop()


def close_code(ws, within_s: float = 15.0):
    """The close code the server sent on ``ws``, or None if it still streams after ``within_s``."""
    end = time.monotonic() + within_s
    try:
        while time.monotonic() < end:
            try:
                ws.recv(timeout=max(end - time.monotonic(), 0.01))
            except TimeoutError:
                return None
    except websockets.exceptions.ConnectionClosed as closed:
        return closed.rcvd.code if closed.rcvd is not None else -1
    return None


def test_the_viewer_websocket_refuses_foreign_origins(tmp_path):
    import viser
    from websockets.sync.client import connect

    vport = free_port()
    srv = ServerProcess(robot="hydrolek", viewer_port=vport, tmp_path=tmp_path)
    try:
        wait_for(lambda: get_or_none(f"http://127.0.0.1:{vport}/"), 60, "the viewer")
        proto = [f"viser-v{viser.__version__}"]
        for origin in ("http://evil.example", f"http://evil.example:{vport}", "http://127.0.0.1:1"):
            with connect(f"ws://127.0.0.1:{vport}", subprotocols=proto, origin=origin, open_timeout=10) as ws:
                assert close_code(ws) == 1008, origin
        # the page's own origin is served (the panel arrives)
        with connect(f"ws://127.0.0.1:{vport}", subprotocols=proto, origin=f"http://127.0.0.1:{vport}",
                     open_timeout=10) as ws:
            assert isinstance(ws.recv(timeout=10), bytes)
        assert "refused a WebSocket from Origin 'http://evil.example'" in srv.log_text()
    finally:
        srv.stop()


def test_a_viewer_websocket_opened_before_the_guard_is_installed_is_checked_too():
    """viser serves from inside its constructor, before the guard exists: installing the guard checks
    the connections already open, so a page that connects in that window is refused all the same."""
    import viser
    from websockets.sync.client import connect

    from web.origin_guard import OriginGuard

    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        port = server.get_port()
        url, proto = f"ws://127.0.0.1:{port}", [f"viser-v{viser.__version__}"]
        with connect(url, subprotocols=proto, origin="http://evil.example", open_timeout=10) as evil, \
                connect(url, subprotocols=proto, origin=f"http://127.0.0.1:{port}", open_timeout=10) as own:
            live = server._websock_server._live_connections
            wait_for(lambda: len(live) == 2, 10, "both connections to be live")
            guard = OriginGuard(server, bind_is_loopback=True)
            assert close_code(evil) == 1008
            assert guard.refused == 1 and len(guard.accepted) == 1
            assert guard.allowed(next(iter(guard.accepted)))
            assert close_code(own, within_s=1.0) is None          # the page's own origin stays open
    finally:
        server.stop()
