"""The in-process monitor at protocol level, no browser: a websocket client reads what viser sends
a browser (joint frames >= 30 Hz, changing, following the plant), and the panel follows the plant.
(``tests/test_web_remote.py``: ``hydrohil serve`` and ``hydrohil view`` as processes.)"""

import time

import httpx
import numpy as np
import pytest

from web_helpers import WINDOW_S, InProcessServer, ViserProbe, frame_rate, wait_for

pytestmark = pytest.mark.realtime


def joint_angle_from_wxyz(scene, dof: str, wxyz) -> float:
    """Undo the fixed joint-origin rotation: q from the quaternion viser was sent for that body."""
    from web.scene import quat_mul

    i = scene.tree.index(dof)
    qt = scene._q_tree[i] * np.array([1.0, -1.0, -1.0, -1.0])  # conjugate of the origin rotation
    qa = quat_mul(qt, np.asarray(wxyz, dtype=float))
    return float(2.0 * np.arctan2(np.dot(qa[1:], scene.tree.axis[i]), qa[0]))


@pytest.fixture(scope="module")
def hydrolek(tmp_path_factory):
    s = InProcessServer("hydrolek", tmp_path_factory.mktemp("web_stream"))
    yield s
    s.close()


def test_joint_transforms_stream_at_30hz(hydrolek):
    s, scene = hydrolek, hydrolek.viewer.scene
    node = scene.body_nodes[scene.tree.index("j1")]
    probe = ViserProbe(s.viewer.port)
    try:
        wait_for(lambda: probe.of_type("GuiButtonMessage") or probe.of_type("SetOrientationMessage"), 20,
                 "the scene to reach the probe")
        with httpx.Client(base_url=s.url, timeout=10) as c:
            c.put("/api/v1/commands", json={"voltages": {"j1": 1.5}}).raise_for_status()
            time.sleep(1.5)  # spool and flow build up; the monitor is past its start-up
            t0 = time.monotonic()
            time.sleep(WINDOW_S)
            t1 = time.monotonic()
            q_end = s.svc.documents.state()["pose"]["j1"]
            c.put("/api/v1/commands", json={"voltages": {"j1": 0.0}}).raise_for_status()
        rate, msgs = frame_rate(probe, node, t0, t1)
        assert rate >= 30.0, f"j1 frame updates at {rate:.1f} Hz over {WINDOW_S} s (need >= 30)"
        angles = np.array([joint_angle_from_wxyz(scene, "j1", m["wxyz"]) for m in msgs])
        assert len(np.unique(np.round(angles, 9))) >= 0.9 * len(angles), "frame values must change"
        assert np.all(np.diff(angles) > 0), "j1 driven one way moves one way"
        assert angles[-1] - angles[0] > 0.1
        assert abs(angles[-1] - q_end) < 0.05  # the browser sees the plant's angle, not something else
        # the cylinders follow at the same rate
        cyl = [m for t, m in probe.of_type("SceneNodeUpdateMessage", name="/actuators")
               if t0 <= t <= t1 and "batched_positions" in m["updates"]]
        assert len(cyl) / (t1 - t0) >= 30.0
        assert not np.allclose(cyl[0]["updates"]["batched_positions"], cyl[-1]["updates"]["batched_positions"])
    finally:
        probe.close()


def test_panel_follows_the_plant(hydrolek):
    s = hydrolek
    panel = s.viewer.panel
    with httpx.Client(base_url=s.url, timeout=10) as c:
        c.put("/api/v1/commands", json={"voltages": {"j3": -0.75}}).raise_for_status()
        wait_for(lambda: "valve <b>-0.75 V</b>" in panel.readouts["j3"].content, 5, "the j3 readout")
        wait_for(lambda: panel.sliders["j3"].value == pytest.approx(-0.75), 5, "the j3 slider to follow REST")
        c.put("/api/v1/commands", json={"voltages": {"j3": 0.0}}).raise_for_status()
    text = panel.readouts["j2"].content
    for unit in ("°", "rad", "V", "bar"):
        assert unit in text
    assert "connected" in panel.status.content and "E-STOP released" in panel.status.content
    assert "Loop health" in panel.health.content and "overruns" in panel.health.content
    # E-STOP from elsewhere shows in the panel and locks the sliders
    s.svc.commands.set_estop(True)
    try:
        wait_for(lambda: "E-STOP ENGAGED" in panel.status.content, 5, "the E-STOP banner")
        assert all(sl.disabled for sl in panel.sliders.values()) and not panel.release_button.disabled
    finally:
        s.svc.commands.set_estop(False)
    wait_for(lambda: not panel.sliders["j1"].disabled, 5, "the sliders to unlock")
    # the plot history carries plant time and commands
    t, v = panel.history.series("j3")
    assert t.size > 20 and np.all(np.diff(t) > 0) and np.nanmin(v[0]) == pytest.approx(-0.75)


def test_the_monitor_shows_a_dead_engine_in_process_and_remotely(tmp_path):
    """The engine is killed: the in-process panel says ENGINE DOWN with the reason and no longer
    draws a state; a remote link loses the stream and reports the engine's state from /health."""
    import os
    import signal

    from web.links import RemoteLink

    s = InProcessServer("hydrolek", tmp_path, engine_restart="never")
    link = None
    try:
        panel = s.viewer.panel
        link = RemoteLink(s.url)
        wait_for(lambda: link.latest() is not None, 10, "the remote stream")
        os.kill(s.svc.supervisor.engine.pid, signal.SIGKILL)
        wait_for(lambda: "ENGINE DOWN" in panel.status.content and "SIGKILL" in panel.status.content, 5,
                 "the panel's engine-down badge and reason")
        assert "SIGKILL" in panel.warnings.content          # the warning box of the panel
        assert s.viewer.link.latest() is None                # nothing shown as if it were the plant
        wait_for(lambda: link.latest() is None and link.status()["engine"].get("state") == "down", 10,
                 "the remote link to report the engine down")
        assert not link.status()["connected"]
    finally:
        if link is not None:
            link.close()
        s.close()
