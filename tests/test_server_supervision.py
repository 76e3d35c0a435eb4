"""Engine supervision on real processes: a killed engine is loud on every interface within 100 ms
(CAN feedback stops, NMT stopped, EMCY; REST 503; metrics; the recording closed with the reason) and
comes back by policy; a stalled one is killed; replies are matched to requests by id; a long lockstep
step does not stall REST; a diverging plant latches the diverged fault until reset."""

import os
import signal
import threading
import time

import can
import cantools
import httpx
import numpy as np
import pytest

from hil_server.can import dbc as D
from sim_core.dataset import read_csv

from server_helpers import ServerProcess

pytestmark = pytest.mark.realtime

DB = cantools.database.load_file(str(D.dbc_path("hydrolek")))
FB_IDS = {m.frame_id for m in DB.messages if m.name.startswith(("JointFeedback_", "JointPressure_"))}
EMCY, HB, STATUS, ENGINE = (DB.get_message_by_name(n) for n in ("Emergency", "Heartbeat", "HilStatus", "EngineStatus"))


class Listener:
    """A stock python-can socketcand client that keeps every frame with the time the server sent it.

    The server's stamp (socketcand's ``SEC.USEC``, taken when the bridge made the frame) and not the
    arrival here: this test process is busy polling REST, so frames can reach it in a late burst.
    """

    def __init__(self, port: int):
        self.bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="vcan0")
        self.frames: list[tuple[float, can.Message]] = []
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self._stop.is_set():
            m = self.bus.recv(0.05)
            if m is not None:
                self.frames.append((m.timestamp, m))

    def decoded(self, message, since=0.0):
        return [(t, message.decode(m.data, decode_choices=False)) for t, m in list(self.frames)
                if m.arbitration_id == message.frame_id and t >= since]

    def close(self):
        self._stop.set()
        self.thread.join(5)
        self.bus.shutdown()


def engine_pid(c) -> int:
    return c.get("/api/v1/health").json()["engine"]["pid"]


def wait_until(pred, timeout, what, interval=0.002):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")


def test_a_killed_engine_is_loud_everywhere_within_100_ms_and_comes_back_neutral(tmp_path):
    srv = ServerProcess("--log-level", "info", robot="hydrolek", can="socketcand", tmp_path=tmp_path)
    lis = Listener(srv.can_port)
    try:
        with srv.client() as c:
            wait_until(lambda: lis.decoded(HB), 3, "a heartbeat")
            c.put("/api/v1/commands", json={"voltages": {"j2": 4.0}}).raise_for_status()
            rec = c.post("/api/v1/recordings", json={"name": "dies"}).json()
            time.sleep(0.5)
            pid = engine_pid(c)
            t_kill = time.time()
            os.kill(pid, signal.SIGKILL)
            r = wait_until(lambda: (lambda x: x if x.status_code == 503 else None)(c.get("/api/v1/state")), 1.0,
                           "REST to refuse the state")
            t_503 = time.time()
            d = wait_until(lambda: (lambda x: x if not x["active"] else None)(c.get(f"/api/v1/recordings/{rec['id']}").json()),
                           1.0, "the recording to close")
            t_closed = time.time()
            assert t_503 - t_kill < 0.1 and t_closed - t_kill < 0.1
            assert "SIGKILL" in r.json()["detail"]
            refused = c.put("/api/v1/commands", json={"voltages": {"j2": 1.0}})
            assert refused.status_code == 503 and "engine" in refused.json()["detail"]
            h = c.get("/api/v1/health").json()
            assert h["status"] == "engine_down" and not h["engine_alive"] and "SIGKILL" in h["engine"]["reason"]
            metrics = c.get("/metrics").text
            assert 'hydrohil_engine_failures_total{kind="died"} 1' in metrics and "hydrohil_engine_up 0" in metrics
            # the recording: closed complete with the reason, one row per tick up to the end
            assert d["complete"] and "engine died" in d["stop_reason"] and "SIGKILL" in d["stop_reason"]
            ds = read_csv(srv.recordings / "dies.csv")
            assert len(ds) == d["rows"] > 300
            np.testing.assert_allclose(np.diff(ds.time), 1e-3, atol=1e-9)
            # CAN: EMCY and NMT stopped within 100 ms, no feedback frame after that
            emcy = [(t, e) for t, e in lis.decoded(EMCY, t_kill) if e["error_code"] == D.EMCY_ENGINE_DIED]
            assert emcy and emcy[0][0] - t_kill < 0.1 and emcy[0][1]["fmi"] == D.FMI_BAD_DEVICE
            stopped = [t for t, hb in lis.decoded(HB, t_kill) if hb["nmt_state"] == D.NMT_STOPPED]
            assert stopped and stopped[0] - t_kill < 0.1
            assert any(s["state"] == D.HIL_ENGINE_DOWN for _, s in lis.decoded(STATUS, t_kill))
            # auto restart: initial state, every valve neutral, boot-up on CAN, restarts counted
            wait_until(lambda: c.get("/api/v1/health").json()["status"] == "ok", 60, "the restarted engine", 0.05)
            t_up = min(t for t, hb in lis.decoded(HB, t_kill) if hb["nmt_state"] == D.NMT_BOOT_UP)
            late_fb = [t for t, m in lis.frames if m.arbitration_id in FB_IDS and t_kill + 0.1 < t < t_up]
            assert not late_fb, f"{len(late_fb)} feedback frames while the engine was down"
            st = c.get("/api/v1/state").json()
            assert st["time"] < 5.0 and all(js["requested_voltage"] == 0.0 for js in st["joints"].values())
            h = c.get("/api/v1/health").json()
            assert h["engine"]["restarts"] == 1 and h["engine"]["pid"] != pid and "SIGKILL" in h["engine"]["last_failure"]
            wait_until(lambda: any(e["restarts"] == 1 and e["engine_state"] == D.ENGINE_RUNNING
                                   for _, e in lis.decoded(ENGINE, t_up)), 2, "EngineStatus with the restart")
            assert any(e["error_code"] == D.EMCY_RESET for _, e in lis.decoded(EMCY, t_up))
            assert c.put("/api/v1/commands", json={"voltages": {"j2": 1.0}}).status_code == 200
        assert "engine restarted" in srv.log_text()
    finally:
        lis.close()
        srv.stop()


def test_a_stalled_engine_is_killed_and_stays_down_with_restart_never(tmp_path):
    srv = ServerProcess("--engine-restart", "never", robot="hydrolek", can="socketcand", tmp_path=tmp_path)
    lis = Listener(srv.can_port)
    try:
        with srv.client() as c:
            wait_until(lambda: lis.decoded(HB), 3, "a heartbeat")
            pid = engine_pid(c)
            t_stop = time.time()
            os.kill(pid, signal.SIGSTOP)           # alive, but the loop makes no progress
            wait_until(lambda: c.get("/api/v1/health").json()["status"] == "engine_down", 1.0, "the stall")
            assert time.time() - t_stop < 0.1 + 0.1    # the 100 ms stall limit, then within 100 ms
            time.sleep(1.5)                           # longer than any restart back-off
            h = c.get("/api/v1/health").json()
            assert h["engine"]["state"] == "down" and h["engine"]["restarts"] == 0
            assert "no progress" in h["engine"]["reason"]
            assert c.get("/api/v1/state").status_code == 503
            assert 'hydrohil_engine_failures_total{kind="stalled"} 1' in c.get("/metrics").text
        assert any(e["error_code"] == D.EMCY_ENGINE_STALLED for _, e in lis.decoded(EMCY, t_stop))
        try:
            with open(f"/proc/{pid}/stat") as fh:
                proc_state = fh.read().split()[2]
        except FileNotFoundError:
            proc_state = "reaped"
        assert proc_state in ("Z", "X", "reaped")     # the stalled engine was killed, not left stopped
    finally:
        lis.close()
        srv.stop()


def test_a_late_reply_is_never_taken_as_the_answer_to_a_later_request():
    from hil_server.engine import shared as S
    from hil_server.engine.process import EngineClient, EngineConfig
    from sim_core.model.spec import load_robot

    spec = load_robot("hydrolek")
    layout = S.Layout(spec.tree.n, len(spec.joints), len(spec.sensed_joints), 1000)
    block = S.SharedBlock(layout)
    eng = EngineClient(spec, EngineConfig(mode="lockstep"), layout, block)
    try:
        with pytest.raises(TimeoutError):
            eng.request("step", 20000, timeout=0.001)     # its reply comes long after we stopped waiting
        assert eng.request("mode", "lockstep", timeout=60) == {"mode": "lockstep"}
        assert eng.dropped_replies == 1
        assert eng.request("step", 3, timeout=60)["tick"] == 20003
    finally:
        eng.stop()
        block.close()


def test_a_long_lockstep_step_does_not_stall_rest(tmp_path):
    srv = ServerProcess("--mode", "lockstep", robot="hydrolek", tmp_path=tmp_path)
    try:
        with srv.client() as c:
            t0 = c.get("/api/v1/state").json()["tick"]
            result = {}
            th = threading.Thread(target=lambda: result.update(
                c.post("/api/v1/step", json={"ticks": 100000}, timeout=600).json()))
            th.start()
            wait_until(lambda: c.get("/api/v1/state").json()["tick"] > t0 + 100, 10, "the step to start", 0.01)
            lat, ticks = [], []
            with srv.client() as probe:
                for k in range(60):
                    a = time.perf_counter()
                    r = probe.get("/api/v1/state" if k % 2 else "/api/v1/health")
                    lat.append(time.perf_counter() - a)
                    assert r.status_code == 200
                    ticks.append(r.json()["tick"])
                    time.sleep(0.02)
            assert th.is_alive(), "the step ended before REST was measured during it"
            th.join(300)
        assert result["tick"] == t0 + 100000
        assert max(lat) < 0.05, f"REST took up to {max(lat) * 1e3:.0f} ms during the step"
        assert ticks[-1] > ticks[0]                      # the plant really stepped meanwhile
    finally:
        srv.stop()


def test_a_diverging_plant_latches_the_diverged_fault_until_reset(tmp_path):
    srv = ServerProcess(robot="hydrolek", can="socketcand", tmp_path=tmp_path)
    lis = Listener(srv.can_port)
    bad = {"integrator.max_substep": 1e-2, "joints.j2.cylinder.bore": 1.0}   # explicit substeps too long for a 1 m bore
    try:
        with srv.client() as c:
            defaults = {p: c.get(f"/api/v1/parameters/{p}").json()["value"] for p in bad}
            c.put("/api/v1/commands", json={"voltages": {"j2": 5.0, "j3": -2.0}}).raise_for_status()
            t_patch = time.time()
            assert c.patch("/api/v1/parameters", json={"values": bad}).status_code == 200
            h = wait_until(lambda: (lambda x: x if x["status"] == "diverged" else None)(c.get("/api/v1/health").json()),
                           2.0, "the diverged fault", 0.01)
            assert not h["engine_alive"] and h["diverged"]["kind"] == "diverged"
            assert set(bad) <= set(h["diverged"]["parameters_changed"]["parameters"])
            st = c.get("/api/v1/state").json()
            assert st["diverged"] and any(f["id"] == "diverged" for f in st["faults"])
            assert all(js["command_voltage"] == 0.0 for js in st["joints"].values())       # valves neutral
            assert all(np.isfinite(js["angle"]) and np.isfinite(js["pressure_a"]) for js in st["joints"].values())
            time.sleep(0.2)
            assert c.get("/api/v1/state").json()["time"] == st["time"]                  # held, not rolled back forever
            assert c.put("/api/v1/commands", json={"voltages": {"j2": 1.0}}).status_code == 409
            assert c.delete("/api/v1/faults/diverged").status_code == 409
            m = c.get("/metrics").text
            assert "hydrohil_plant_diverged 1" in m and "hydrohil_plant_diverged_total 1" in m
            rollbacks = int(next(ln for ln in m.splitlines() if ln.startswith("hydrohil_plant_rollbacks_total")).split()[-1])
            assert rollbacks >= 5
            wait_until(lambda: any(e["error_code"] == D.EMCY_DIVERGED for _, e in lis.decoded(EMCY, t_patch)), 1,
                       "EMCY diverged")
            log = srv.log_text()
            assert "plant diverged" in log and "joints.j2.cylinder.bore" in log and "q = " in log and "p_a = " in log
            # fix the parameters, reset: the plant runs again
            c.patch("/api/v1/parameters", json={"values": defaults}).raise_for_status()
            t_reset = time.time()
            c.post("/api/v1/reset", json={}).raise_for_status()
            h = c.get("/api/v1/health").json()
            assert h["status"] == "ok" and h["engine_alive"] and h["diverged"] is None
            t1 = c.get("/api/v1/state").json()["time"]
            time.sleep(0.2)
            assert c.get("/api/v1/state").json()["time"] > t1 + 0.1
            assert c.put("/api/v1/commands", json={"voltages": {"j2": 1.0}}).status_code == 200
            wait_until(lambda: any(e["error_code"] == D.EMCY_RESET and e["fmi"] == D.EMCY_CODES[D.EMCY_DIVERGED][0]
                                   for _, e in lis.decoded(EMCY, t_reset)), 1, "EMCY reset")
    finally:
        lis.close()
        srv.stop()
