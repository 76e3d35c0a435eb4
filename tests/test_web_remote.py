"""The monitor as the commands start it, no browser: ``hydrohil serve`` starts the viewer plugin, and
``hydrohil view`` attaches to a remote server through REST + WebSocket (frames >= 30 Hz, token,
E-STOP, connection state). One server at a time: each engine spins a little before every tick."""

import time

import httpx
import numpy as np
import pytest

from server_helpers import ServerProcess
from web_helpers import WINDOW_S, ViewProcess, ViserProbe, frame_rate, free_port, get_or_none, wait_for

pytestmark = pytest.mark.realtime


def test_serve_starts_the_viewer(tmp_path):
    port = free_port()
    srv = ServerProcess(robot="harvester", tmp_path=tmp_path, viewer_port=port)
    try:
        # REST is up; the viewer comes up beside it in the background
        page = wait_for(lambda: get_or_none(f"http://127.0.0.1:{port}/"), 60, "the viewer's page")
        assert page.status_code == 200 and "<html" in page.text.lower()
        probe = ViserProbe(port)
        try:
            wait_for(lambda: any(m.get("props", {}).get("label") == "E-STOP" for _, m in probe.messages), 20,
                     "the operator panel")
            nodes = {m.get("name") for _, m in probe.messages}
            for n in ("/robot/turret", "/robot/turret/boom_link", "/actuators"):
                assert n in nodes
            wait_for(lambda: f"browser monitor at http://127.0.0.1:{port}/" in srv.log_path.read_text(), 30,
                     "the viewer's start-up line in the log")
        finally:
            probe.close()
    finally:
        srv.close()


def test_view_attaches_to_a_remote_server(tmp_path):
    token = "s3cret"
    srv = ServerProcess(robot="hydrolek", tmp_path=tmp_path, viewer_port=0, token=token)
    view = None
    try:
        view = ViewProcess(srv.url, tmp_path, token=token)
        probe = ViserProbe(view.port)
        try:
            node = "/robot/link1"
            wait_for(lambda: probe.of_type("SetOrientationMessage", name=node) or
                     any(m.get("name") == node for _, m in probe.messages), 30, "the remote scene")
            with httpx.Client(base_url=srv.url, headers=srv.headers(), timeout=10) as c:
                c.put("/api/v1/commands", json={"voltages": {"j1": -1.5}}).raise_for_status()
                time.sleep(1.5)  # past start-up: the steady stream is what is measured
                t0 = time.monotonic()
                time.sleep(WINDOW_S)
                t1 = time.monotonic()
                c.put("/api/v1/commands", json={"voltages": {"j1": 0.0}}).raise_for_status()
            rate, msgs = frame_rate(probe, node, t0, t1)
            assert rate >= 30.0, f"remote monitor: j1 frame updates at {rate:.1f} Hz (need >= 30)"
            assert len({tuple(np.round(m["wxyz"], 9)) for m in msgs}) >= 0.9 * len(msgs)
            status = [m["updates"]["content"] for _, m in probe.of_type("GuiUpdateMessage")
                      if "content" in m.get("updates", {}) and "hydrolek" in m["updates"]["content"]]
            assert status and "connected" in status[-1] and srv.url in status[-1]
        finally:
            probe.close()
    finally:
        if view is not None:
            assert view.close() == 0
        srv.close()


def test_remote_link_commands_token_estop_and_connection_state(tmp_path):
    from web.links import LinkError, RemoteLink

    token = "t0ken"
    srv = ServerProcess(robot="hydrolek", tmp_path=tmp_path, viewer_port=0, token=token)
    links = []
    try:
        # without a token: read-only, and says so
        ro = RemoteLink(srv.url)
        links.append(ro)
        assert ro.auth_required and not ro.can_command
        with pytest.raises(LinkError, match="token"):
            ro.set_voltages({"j2": 1.0})
        wait_for(lambda: ro.latest() is not None, 10, "the state stream")
        assert ro.latest()["robot"] == "hydrolek" and ro.status()["connected"]
        # a wrong token: the refusal reaches the operator
        bad = RemoteLink(srv.url, "wrong")
        links.append(bad)
        refused = []
        bad.errors.append(refused.append)
        bad.set_voltages({"j2": 1.0})
        wait_for(lambda: refused, 10, "the refusal")
        assert "403" in refused[0]
        # the right token: commands reach the plant (coalesced: the last value wins), E-STOP works
        ok = RemoteLink(srv.url, token)
        links.append(ok)
        for v in (0.5, 1.0, 1.25):
            ok.set_voltages({"j2": v})
        with httpx.Client(base_url=srv.url, timeout=10) as c:
            wait_for(lambda: c.get("/api/v1/state").json()["joints"]["j2"]["requested_voltage"] == 1.25, 10,
                     "the remote command")
            c.put("/api/v1/commands", json={"voltages": {"j4": 2.0}}, headers=srv.headers()).raise_for_status()
            ok.set_estop(True)
            # the latch is set when the call returns; the state document is the engine's, from its next tick
            assert c.get("/api/v1/estop").json()["engaged"]

            def stopped():
                st = c.get("/api/v1/state").json()
                return st["estop"] and all(js["requested_voltage"] == 0.0 for js in st["joints"].values())

            wait_for(stopped, 5, "the engine to apply the E-STOP")
            wait_for(lambda: all(js["command_voltage"] == 0.0
                                 for js in c.get("/api/v1/state").json()["joints"].values()),
                     5, "every valve neutral")
            ok.set_estop(False)
            assert not c.get("/api/v1/estop").json()["engaged"]
        # the server goes away: the link says so
        srv.close()
        wait_for(lambda: not ok.status()["connected"], 10, "the link to notice the server is gone")
        assert ok.status()["detail"] != "streaming"
    finally:
        for link in links:
            link.close()
        srv.close()


def test_view_reports_an_unreachable_server(tmp_path):
    from conftest import run_cli

    proc = run_cli("view", "--url", f"http://127.0.0.1:{free_port()}", "--port", str(free_port()), timeout=60)
    assert proc.returncode == 2
    assert "cannot reach" in proc.stderr
