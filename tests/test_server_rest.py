"""The REST service on a real uvicorn server: contract keys, validation, modes, faults, recordings."""

import json
import math
import time

import httpx
import numpy as np
import pytest

from sim_core.dataset import read_csv

from server_helpers import ServerProcess

pytestmark = pytest.mark.realtime

JOINT_KEYS = {"angle", "sensor_voltage", "command_voltage", "pressure_a", "pressure_b", "velocity"}


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    s = ServerProcess(tmp_path=tmp_path_factory.mktemp("srv"))
    yield s
    s.stop()


@pytest.fixture
def http(server):
    with server.client() as c:
        c.put("/api/v1/mode", json={"mode": "realtime"})
        c.put("/api/v1/estop", json={"engaged": False})
        c.delete("/api/v1/faults")
        c.post("/api/v1/commands/neutral")
        yield c


def wait_time(c, dt):
    t0 = c.get("/api/v1/state").json()["time"]
    while c.get("/api/v1/state").json()["time"] < t0 + dt:
        time.sleep(0.02)


def test_health_reports_loop_priority(http):
    h = http.get("/api/v1/health").json()
    assert h["status"] == "ok" and h["robot"] == "hydrolek" and h["engine_alive"]
    assert isinstance(h["realtime_priority"], bool) and h["realtime_note"]
    assert h["mode"] == "realtime" and h["rate_hz"] == 1000.0


def test_state_contract_and_time_advances_in_realtime(http):
    s0 = http.get("/api/v1/state").json()
    assert set(s0["joints"]) == {f"j{k}" for k in range(1, 8)}
    for j, v in s0["joints"].items():
        assert JOINT_KEYS <= set(v)
    assert s0["joints"]["j6"]["sensor_voltage"] is None and s0["joints"]["j2"]["sensor_voltage"] is not None
    assert {"rate_hz", "overruns", "lateness_us"} <= set(s0["loop"])
    t_wall = time.time()
    time.sleep(1.0)
    s1 = http.get("/api/v1/state").json()
    elapsed = time.time() - t_wall
    assert (s1["time"] - s0["time"]) == pytest.approx(elapsed, abs=0.2)   # realtime: sim time follows wall time
    assert s1["loop"]["ticks"] > s0["loop"]["ticks"]


def test_commands_move_the_joint_and_show_in_state(http):
    a0 = http.get("/api/v1/state").json()["joints"]["j2"]["angle"]
    r = http.put("/api/v1/commands", json={"voltages": {"j2": 4.0}})
    assert r.status_code == 200 and r.json()["applied"] == {"j2": 4.0}
    wait_time(http, 0.5)
    s = http.get("/api/v1/state").json()["joints"]["j2"]
    assert s["command_voltage"] == 4.0 and s["angle"] > a0 + 0.02 and s["velocity"] > 0.05


@pytest.mark.parametrize("body,reason", [
    ({"voltages": {"j9": 1.0}}, "unknown joint"),
    ({"voltages": {"j2": 12.0}}, "outside the command range"),
    ({"voltages": {"j2": "fast"}}, "float"),
    ({"voltages": {}}, "at least 1"),
    ({"voltage": {"j2": 1.0}}, "missing"),
    ({"voltages": {"j2": 1.0}, "extra": 1}, "Extra inputs"),
])
def test_bad_commands_get_422_with_a_reason_and_do_not_reach_the_plant(http, body, reason):
    before = http.get("/api/v1/commands").json()["voltages"]
    r = http.put("/api/v1/commands", json=body)
    assert r.status_code == 422
    assert reason in json.dumps(r.json())
    assert http.get("/api/v1/commands").json()["voltages"] == before


def test_nan_and_infinity_are_refused(http):
    for literal in ("NaN", "Infinity", "-Infinity"):
        r = http.put("/api/v1/commands", content='{"voltages": {"j2": %s}}' % literal,
                     headers={"content-type": "application/json"})
        assert r.status_code == 422, literal
    st = http.get("/api/v1/state").json()
    assert all(math.isfinite(v["command_voltage"]) for v in st["joints"].values())


def test_lockstep_advances_exactly_n_ticks_and_is_deterministic(http):
    assert http.post("/api/v1/step", json={"ticks": 5}).status_code == 409   # realtime: refused
    assert http.put("/api/v1/mode", json={"mode": "lockstep"}).json()["mode"] == "lockstep"
    poses = []
    for _ in range(2):
        http.post("/api/v1/reset", json={"seed": 3})
        t0 = http.get("/api/v1/state").json()["time"]
        time.sleep(0.2)
        assert http.get("/api/v1/state").json()["time"] == t0             # nothing moves on its own
        http.put("/api/v1/commands", json={"voltages": {"j2": 5.0, "j3": -3.0}})
        r = http.post("/api/v1/step", json={"ticks": 250})
        assert r.status_code == 200
        st = http.get("/api/v1/state").json()
        assert st["time"] - t0 == pytest.approx(0.25, abs=1e-9)
        poses.append((st["pose"], {j: v["sensor_voltage"] for j, v in st["joints"].items()}))
    assert poses[0] == poses[1]
    assert http.post("/api/v1/step", json={"ticks": 0}).status_code == 422


def test_paused_mode_freezes_time(http):
    http.put("/api/v1/mode", json={"mode": "paused"})
    t0 = http.get("/api/v1/state").json()["time"]
    time.sleep(0.3)
    assert http.get("/api/v1/state").json()["time"] == t0
    assert http.put("/api/v1/mode", json={"mode": "warp"}).status_code == 422


def test_parameters_read_and_patch_by_path(http):
    p = http.get("/api/v1/parameters").json()
    assert p["values"]["supply.pressure"] == 14e6
    assert http.get("/api/v1/parameters/joints.j2.valve.rated_flow").json()["value"] == pytest.approx(4.17e-5)
    r = http.patch("/api/v1/parameters", json={"values": {"supply.pressure": 12e6}})
    assert r.status_code == 200
    wait_time(http, 0.1)
    assert http.get("/api/v1/state").json()["supply_pressure"] == pytest.approx(12e6)
    bad = http.patch("/api/v1/parameters", json={"values": {"supply.pressure": -1}})
    assert bad.status_code == 422 and "supply.pressure" in bad.text
    assert http.patch("/api/v1/parameters", json={"values": {"joints.j2.valve.warp": 1}}).status_code == 422
    assert http.get("/api/v1/parameters/nope").status_code == 404
    http.patch("/api/v1/parameters", json={"values": {"supply.pressure": 14e6}})
    # effects
    assert http.put("/api/v1/effects/deadband", json={"joint": "j2", "params": {"width": 20}}).status_code == 422
    assert http.put("/api/v1/effects/deadband", json={"joint": "j2", "params": {"width": 4.0}}).status_code == 200
    http.put("/api/v1/commands", json={"voltages": {"j2": 3.5}})
    a0 = http.get("/api/v1/state").json()["joints"]["j2"]["angle"]
    wait_time(http, 0.3)
    assert abs(http.get("/api/v1/state").json()["joints"]["j2"]["angle"] - a0) < 2e-3   # inside the deadband
    assert http.delete("/api/v1/effects/deadband", params={"joint": "j2"}).status_code == 200
    assert http.delete("/api/v1/effects/deadband", params={"joint": "j2"}).status_code == 404


def test_fault_injection_and_clearing(http):
    bad = http.post("/api/v1/faults", json={"kind": "sensor_stuck", "joint": "j9", "value": 2.0})
    assert bad.status_code == 422
    assert http.post("/api/v1/faults", json={"kind": "sensor_stuck", "joint": "j6", "value": 2.0}).status_code == 422
    assert http.post("/api/v1/faults", json={"kind": "meteor", "joint": "j2"}).status_code == 422
    f = http.post("/api/v1/faults", json={"kind": "sensor_stuck", "joint": "j2", "value": 2.5}).json()
    wait_time(http, 0.05)
    assert http.get("/api/v1/state").json()["joints"]["j2"]["sensor_voltage"] == pytest.approx(2.5, abs=1e-3)
    assert http.delete(f"/api/v1/faults/{f['id']}").status_code == 200
    wait_time(http, 0.05)
    assert http.get("/api/v1/state").json()["joints"]["j2"]["sensor_voltage"] != pytest.approx(2.5, abs=1e-3)
    sag = http.post("/api/v1/faults", json={"kind": "supply_sag", "factor": 0.5}).json()
    wait_time(http, 0.05)
    assert http.get("/api/v1/state").json()["supply_pressure"] == pytest.approx(7e6)
    assert sag["id"] in {x["id"] for x in http.get("/api/v1/faults").json()["faults"]}
    # a burst hose on j2 loses the load-holding pressure: the shoulder sags
    a0 = http.get("/api/v1/state").json()["joints"]["j2"]["angle"]
    http.post("/api/v1/faults", json={"kind": "hose_burst", "joint": "j2"})
    wait_time(http, 0.5)
    assert http.get("/api/v1/state").json()["joints"]["j2"]["angle"] < a0 - 0.01
    http.delete("/api/v1/faults")
    assert http.get("/api/v1/faults").json()["faults"] == []
    assert http.delete("/api/v1/faults/nothing").status_code == 404


def test_estop_neutralises_every_valve_until_released(http):
    http.put("/api/v1/commands", json={"voltages": {"j1": 3.0, "j2": -4.0, "j7": 2.0}})
    wait_time(http, 0.05)
    assert http.put("/api/v1/estop", json={"engaged": True}).json()["engaged"] is True
    http.put("/api/v1/commands", json={"voltages": {"j2": 5.0}})    # refused by the latch
    wait_time(http, 0.05)
    st = http.get("/api/v1/state").json()
    assert st["estop"] and all(v["command_voltage"] == 0.0 for v in st["joints"].values())
    http.put("/api/v1/estop", json={"engaged": False})
    http.put("/api/v1/commands", json={"voltages": {"j2": 5.0}})
    wait_time(http, 0.05)
    assert http.get("/api/v1/state").json()["joints"]["j2"]["command_voltage"] == 5.0


def test_cfp_channel_view(http):
    mods = http.get("/api/v1/cfp").json()["modules"]
    assert {"cFP1", "cFP2", "cFP3"} <= set(mods)
    ai = {c["channel"]: c for c in mods["cFP3"]}
    assert ai["AI1"]["joint"] == "j2" and ai["AI1"]["direction"] == "input"
    assert http.put("/api/v1/cfp/cFP1/AO3", json={"value": 4.0}).status_code == 200   # j2 amplifier B
    assert http.get("/api/v1/commands").json()["voltages"]["j2"] == -4.0
    assert http.get("/api/v1/cfp/cFP1/AO3").json()["value"] == 4.0
    assert http.get("/api/v1/cfp/cFP1/AO2").json()["value"] == 0.0
    st = http.get("/api/v1/state").json()
    assert http.get("/api/v1/cfp/cFP3/AI1").json()["value"] == pytest.approx(st["joints"]["j2"]["sensor_voltage"], abs=0.05)
    assert http.put("/api/v1/cfp/cFP3/AI1", json={"value": 1.0}).status_code == 422
    assert http.put("/api/v1/cfp/cFP1/AO3", json={"value": 11.0}).status_code == 422
    assert http.get("/api/v1/cfp/cFP9/AO0").status_code == 404


def test_websocket_stream_at_the_chosen_rate(server, http):
    import asyncio

    import websockets

    async def collect(rate, seconds):
        msgs = []
        async with websockets.connect(server.url.replace("http", "ws") + f"/api/v1/stream?rate={rate}") as ws:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                msgs.append(json.loads(await ws.recv()))
        return msgs

    msgs = asyncio.run(collect(50, 2.0))
    assert 60 <= len(msgs) <= 110      # paced at the chosen rate: never faster, and steady
    times = [m["time"] for m in msgs]
    assert all(b > a for a, b in zip(times, times[1:]))

    async def bad():
        async with websockets.connect(server.url.replace("http", "ws") + "/api/v1/stream?rate=0") as ws:
            await ws.recv()

    with pytest.raises(websockets.exceptions.WebSocketException):
        asyncio.run(bad())


def test_prometheus_metrics(http):
    http.get("/api/v1/state")
    text = http.get("/metrics").text
    assert "# TYPE hydrohil_loop_lateness_seconds histogram" in text
    assert 'hydrohil_loop_lateness_seconds_bucket{le="+Inf"}' in text
    assert "hydrohil_loop_overruns_total" in text
    line = [l for l in text.splitlines() if l.startswith('hydrohil_http_requests_total{method="GET",route="/api/v1/state",status="200"}')]
    assert line and int(line[0].split()[-1]) >= 1


def test_recording_under_load_has_every_tick_once(server, http):
    import threading

    rec = http.post("/api/v1/recordings", json={"name": "load_test"}).json()
    assert http.post("/api/v1/recordings", json={"name": "second"}).status_code == 409
    stop = threading.Event()
    count = [0]

    def hammer():
        with server.client() as c:
            while not stop.is_set():
                c.get("/api/v1/state")
                c.put("/api/v1/commands", json={"voltages": {"j2": 3.0 if count[0] % 2 else -3.0}})
                count[0] += 1

    threads = [threading.Thread(target=hammer) for _ in range(4)]
    for t in threads:
        t.start()
    time.sleep(3.0)
    stop.set()
    for t in threads:
        t.join()
    done = http.post("/api/v1/recordings/stop").json()
    assert done["complete"] and not done["active"] and count[0] > 100
    csv = http.get(f"/api/v1/recordings/{rec['id']}/data")
    assert csv.status_code == 200
    path = server.recordings / "check.csv"
    path.write_text(csv.text)
    ds = read_csv(path)
    assert ds.columns[:2] == ["time", "u_j1"] and "q_j2" in ds.columns and "p_j7_b" in ds.columns
    d = np.diff(ds.time)
    assert len(ds) == done["rows"] and len(ds) > 2500
    np.testing.assert_allclose(d, 1e-3, atol=1e-9)      # one row per tick: none missing, none twice
    assert set(np.unique(ds["u_j2"])) <= {3.0, -3.0, 0.0}
    assert http.get("/api/v1/recordings").json()["recordings"][0]["id"] == "load_test"
    assert http.get("/api/v1/recordings/nope/data").status_code == 404


def test_an_idle_keep_alive_connection_outlives_the_clients_pool_expiry(server):
    """The server must not close an idle connection before a client's pool would (httpx: 5 s idle):
    otherwise a request sent just before the client's expiry can meet the server's close and fail."""
    import http.client
    from urllib.parse import urlsplit

    expiry = httpx.Limits(max_connections=None).keepalive_expiry
    u = urlsplit(server.url)
    conn = http.client.HTTPConnection(u.hostname, u.port, timeout=30)
    try:
        conn.request("GET", "/api/v1/health", headers=server.headers())
        first = conn.getresponse()
        first.read()
        sock = conn.sock
        assert first.status == 200 and sock is not None and not first.will_close
        time.sleep(expiry + 1.0)
        conn.request("GET", "/api/v1/health", headers=server.headers())
        again = conn.getresponse()        # a closed connection: RemoteDisconnected here
        again.read()
        assert again.status == 200 and conn.sock is sock   # the same connection, still open
    finally:
        conn.close()
