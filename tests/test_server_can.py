"""CAN: the DBC contract, the virtual bus in-process, socketcand across processes, watchdog, bad frames."""

import json
import subprocess
import sys
import threading
import time

import can
import cantools
import httpx
import numpy as np
import pytest

from hil_server.can import dbc as D
from hil_server.service import HilService, ServiceConfig
from sim_core.model.spec import available_robots, load_robot

from server_helpers import ROOT, ServerProcess, free_port

pytestmark = pytest.mark.realtime


def test_dbc_is_shipped_for_every_robot_with_the_contract_names(cli):
    for robot in available_robots():
        spec = load_robot(robot)
        db = cantools.database.load_file(str(D.dbc_path(robot)))
        names = {m.name for m in db.messages}
        for j in spec.joint_names:
            assert {f"ValveCommand_{j}", f"JointFeedback_{j}"} <= names
            assert {s.name for s in db.get_message_by_name(f"ValveCommand_{j}").signals} >= {"voltage"}
            fb = {s.name: s for s in db.get_message_by_name(f"JointFeedback_{j}").signals}
            assert {"angle", "sensor_voltage", "counter"} <= set(fb)
            assert fb["angle"].unit == "rad" and fb["sensor_voltage"].unit == "V"
        assert {"HilStatus", "Heartbeat", "Emergency", "Sync"} <= names
        # the shipped file is what the generator writes for the robot's joints (single source in step)
        text = D.generate_dbc(robot, spec.joint_names, [j.sensed for j in spec.joints],
                              [j.command_range for j in spec.joints])
        assert D.dbc_path(robot).read_text() == text
    out = cli("dbc", "--robot", "harvester", check=True).stdout
    assert "ValveCommand_boom" in out and "JointFeedback_stick" in out


@pytest.fixture(scope="module")
def virtual_service(tmp_path_factory):
    svc = HilService(ServiceConfig(robot="hydrolek", can="virtual:hil_test", viewer_port=None, watchdog_ms=100.0,
                                   feedback_rate_hz=100.0, recordings_dir=str(tmp_path_factory.mktemp("rec"))))
    svc.start_transports()
    yield svc
    svc.close()


@pytest.fixture
def bus():
    b = can.Bus(interface="virtual", channel="hil_test", receive_own_messages=False)
    yield b
    b.shutdown()


def collect(bus, seconds):
    out = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        m = bus.recv(0.01)
        if m is not None:
            out.append(m)
    return out


def test_virtual_bus_commands_feedback_and_watchdog(virtual_service, bus):
    svc = virtual_service
    db = cantools.database.load_file(str(D.dbc_path("hydrolek")))
    cmd = db.get_message_by_name("ValveCommand_j2")
    fb = db.get_message_by_name("JointFeedback_j2")
    emcy = db.get_message_by_name("Emergency")
    a0 = svc.documents.state()["joints"]["j2"]["angle"]
    frames = []
    for k in range(50):   # 0.5 s of commands at 100 Hz
        bus.send(can.Message(arbitration_id=cmd.frame_id, data=cmd.encode({"voltage": 4.0, "counter": k}),
                             is_extended_id=False))
        frames += collect(bus, 0.01)
    st = svc.documents.state()["joints"]["j2"]
    assert st["command_voltage"] == 4.0 and st["source"] == "can" and not st["watchdog"]
    assert st["angle"] > a0 + 0.02
    fbs = [fb.decode(m.data) for m in frames if m.arbitration_id == fb.frame_id]
    assert len(fbs) >= 30 and fbs[-1]["angle"] == pytest.approx(st["angle"], abs=0.01)
    assert len({f["counter"] for f in fbs}) == len(fbs)          # rolling counter
    # silence: the watchdog puts the valve neutral within 100 ms and says why
    frames = collect(bus, 0.4)
    st = svc.documents.state()["joints"]["j2"]
    assert st["watchdog"] and st["command_voltage"] == 0.0 and st["requested_voltage"] == 4.0
    em = [emcy.decode(m.data) for m in frames if m.arbitration_id == emcy.frame_id]
    assert any(e["error_code"] == D.EMCY_TIMEOUT and e["joint"] == 1 and e["fmi"] == D.FMI_TIMEOUT for e in em)
    status = db.get_message_by_name("HilStatus")
    sts = [status.decode(m.data, decode_choices=False) for m in frames if m.arbitration_id == status.frame_id]
    assert sts and sts[-1]["watchdog_mask"] & (1 << 1) and sts[-1]["state"] == 1
    # the next command recovers
    bus.send(can.Message(arbitration_id=cmd.frame_id, data=cmd.encode({"voltage": -2.0, "counter": 1}), is_extended_id=False))
    frames = collect(bus, 0.05)
    st = svc.documents.state()["joints"]["j2"]
    assert not st["watchdog"] and st["command_voltage"] == -2.0
    em = [emcy.decode(m.data) for m in frames + collect(bus, 0.05) if m.arbitration_id == emcy.frame_id]
    assert any(e["error_code"] == D.EMCY_RESET and e["joint"] == 1 for e in em)
    assert svc.documents.loop_stats()["watchdog_trips"] >= 1


def test_bad_frames_are_counted_and_ignored_while_the_loop_keeps_its_rate(virtual_service, bus):
    svc = virtual_service
    db = cantools.database.load_file(str(D.dbc_path("hydrolek")))
    cmd = db.get_message_by_name("ValveCommand_j3")
    before = dict(svc.bridge.counters)
    u0 = svc.commands.voltages()["j3"]
    bus.send(can.Message(arbitration_id=cmd.frame_id, data=b"\x01\x02", is_extended_id=False))          # wrong DLC
    bus.send(can.Message(arbitration_id=0x5A5, data=b"\x00" * 8, is_extended_id=False))                  # unknown id
    bus.send(can.Message(arbitration_id=cmd.frame_id, is_remote_frame=True, dlc=4, is_extended_id=False))  # remote
    bus.send(can.Message(arbitration_id=cmd.frame_id, data=cmd.encode({"voltage": 9.9, "counter": 0})[:2] + b"\x00\x80",
                         is_extended_id=False))  # counter byte garbage but valid length: accepted
    big = int(12.0 / 0.001).to_bytes(2, "little", signed=True) + b"\x00\x00"
    bus.send(can.Message(arbitration_id=cmd.frame_id, data=big, is_extended_id=False))                    # 12 V: out of range
    time.sleep(0.2)
    c = svc.bridge.counters
    assert c.get(("rx", "wrong_dlc"), 0) > before.get(("rx", "wrong_dlc"), 0)
    assert c.get(("rx", "unknown_id"), 0) > before.get(("rx", "unknown_id"), 0)
    assert c.get(("rx", "remote_frame"), 0) > before.get(("rx", "remote_frame"), 0)
    assert c.get(("rx", "out_of_range"), 0) > before.get(("rx", "out_of_range"), 0)
    assert svc.commands.voltages()["j3"] == pytest.approx(9.9)     # the valid frame counted, 12 V ignored
    # a flood: every frame is counted (as unknown or, beyond the budget, as flood); the plant keeps 1 kHz
    stop = threading.Event()
    sent = [0]

    def flood():
        m = can.Message(arbitration_id=0x5A5, data=b"\xff" * 8, is_extended_id=False)
        while not stop.is_set():
            for _ in range(200):
                bus.send(m)
            sent[0] += 200

    def accounted():
        c = svc.bridge.counters
        return sum(c.get(("rx", k), 0) - before_flood.get(("rx", k), 0) for k in ("flood_dropped", "unknown_id"))

    before_flood = dict(svc.bridge.counters)
    t0 = svc.block.stats.copy()
    w0 = time.monotonic()
    th = threading.Thread(target=flood)
    th.start()
    time.sleep(2.0)
    stop.set()
    th.join()
    elapsed = time.monotonic() - w0
    ticks = svc.documents.loop_stats()["ticks"] - int(t0[0])
    assert ticks == pytest.approx(1000 * elapsed, rel=0.05)
    assert sent[0] > 0
    deadline = time.monotonic() + 30.0
    while accounted() < sent[0] and time.monotonic() < deadline:
        time.sleep(0.05)
    assert accounted() == sent[0]          # nothing silently lost, nothing counted twice
    svc.commands.write({2: u0}, 1.0)


@pytest.mark.slow
def test_external_controller_holds_a_joint_over_socketcand_in_lockstep(tmp_path):
    port = free_port()
    server = ServerProcess("--mode", "lockstep", robot="hydrolek", can=f"socketcand:{port}", tmp_path=tmp_path)
    try:
        results = []
        for _ in range(2):
            with server.client() as c:
                c.post("/api/v1/reset", json={"seed": 1})
            out = subprocess.run([sys.executable, str(ROOT / "tests" / "can_p_controller.py"), str(port),
                                  str(D.dbc_path("hydrolek")), "j2", "0.1", "3000", "40.0"],
                                 capture_output=True, text=True, timeout=300)
            assert out.returncode == 0, out.stderr
            results.append(json.loads(out.stdout))
        with server.client() as c:
            st = c.get("/api/v1/state").json()
        assert results[0]["first"] == pytest.approx(-0.3, abs=0.01)
        # P loop: gain ~40 V/rad x ~0.05 rad/s/V -> time constant ~0.5 s; after 3 s (6 tau) within 5 mrad
        assert results[0]["final"] == pytest.approx(0.1, abs=0.005)       # held at the setpoint
        assert st["joints"]["j2"]["angle"] == pytest.approx(0.1, abs=0.005)
        assert st["time"] == pytest.approx(3.001, abs=1e-6)               # exactly one tick per SYNC (+1 to start)
        assert results[0]["digest"] == results[1]["digest"]               # lockstep is deterministic
    finally:
        server.stop()
