"""Kernel-free and kernel CAN across processes: a stock python-can program (its own process, the
shipped DBC, no code of ours) commands the arm through ``hydrohil serve --can udp_multicast:...`` and
reads its feedback; the same over ``--can socketcan:vcan0`` where the kernel has vcan."""

import json
import random
import socket
import subprocess
import sys
import time

import can
import pytest

from hil_server.can import dbc as D

from server_helpers import ServerProcess

pytestmark = pytest.mark.realtime

STOCK_CLIENT = r"""
import json, sys, time, can, cantools
bus_kw, dbc = json.loads(sys.argv[1]), sys.argv[2]
db = cantools.database.load_file(dbc)
cmd, fb, hb = (db.get_message_by_name(n) for n in ("ValveCommand_j2", "JointFeedback_j2", "Heartbeat"))
bus = can.Bus(**bus_kw)
angles, counters, heartbeats, sent = [], [], [], 0
start = time.monotonic()
while time.monotonic() - start < 1.5:
    bus.send(can.Message(arbitration_id=cmd.frame_id, data=cmd.encode({"voltage": 4.0, "counter": sent & 0xFF}),
                         is_extended_id=False))
    sent += 1
    end = start + sent * 0.01
    while time.monotonic() < end:
        m = bus.recv(max(0.0, end - time.monotonic()))
        if m is None:
            continue
        if m.arbitration_id == fb.frame_id:
            d = fb.decode(m.data)
            angles.append(d["angle"])
            counters.append(d["counter"])
        elif m.arbitration_id == hb.frame_id:
            heartbeats.append(hb.decode(m.data, decode_choices=False)["nmt_state"])
bus.shutdown()
print(json.dumps({"sent": sent, "angles": angles, "counters": counters, "heartbeats": heartbeats}))
"""


def run_stock_client(bus_kw: dict) -> dict:
    out = subprocess.run([sys.executable, "-c", STOCK_CLIENT, json.dumps(bus_kw), str(D.dbc_path("hydrolek"))],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def check_the_arm_was_driven(srv, result: dict) -> None:
    with srv.client() as c:
        st = c.get("/api/v1/state").json()["joints"]["j2"]
        frames = c.get("/api/v1/health").json()["can"]["frames"]
    assert st["source"] == "can" and st["requested_voltage"] == pytest.approx(4.0)
    assert frames.get("rx.command") == result["sent"]            # every command arrived, once
    assert frames.get("rx.unknown_id", 0) == 0                   # and nothing else (no echo of our own frames)
    angles = result["angles"]
    assert len(angles) > 100                                      # 100 Hz feedback for 1.5 s
    assert angles[-1] > angles[0] + 0.02                          # the boom moved up under +4 V
    assert len(set(result["counters"])) > 50 and 5 in result["heartbeats"]


def multicast_problem(group: str, port: int) -> str | None:
    """Why this host cannot carry python-can's UDP multicast between two sockets, or None."""
    try:
        a = can.Bus(interface="udp_multicast", channel=group, port=port)
        b = can.Bus(interface="udp_multicast", channel=group, port=port)
    except Exception as exc:  # noqa: BLE001
        return f"cannot open a udp_multicast bus: {exc}"
    try:
        a.send(can.Message(arbitration_id=0x7FF, data=b"\x01", is_extended_id=False))
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            m = b.recv(0.1)
            if m is not None and m.arbitration_id == 0x7FF:
                return None
        return f"no multicast delivery between two sockets on {group}:{port} (no multicast route?)"
    finally:
        a.shutdown()
        b.shutdown()


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("", 0))
        return s.getsockname()[1]


def test_a_stock_python_can_program_drives_the_arm_over_udp_multicast(tmp_path):
    group, port = f"239.74.{random.randint(1, 254)}.{random.randint(1, 254)}", free_udp_port()
    problem = multicast_problem(group, port)
    if problem:
        pytest.skip(problem)
    srv = ServerProcess(robot="hydrolek", can=f"udp_multicast:{group}@{port}", tmp_path=tmp_path)
    try:
        result = run_stock_client({"interface": "udp_multicast", "channel": group, "port": port})
        check_the_arm_was_driven(srv, result)
        with srv.client() as c:
            h = c.get("/api/v1/health").json()
        assert h["can"]["frames"]["transport.own_echo"] > 100        # its own frames came back and were dropped
        assert not any("udp_multicast" in w for w in h["warnings"])  # host-only by default: nothing to warn about
    finally:
        srv.stop()


def test_the_udp_multicast_transport_rejects_a_bad_group_clearly(cli):
    proc = cli("serve", "--viewer-port", "0", "--port", "0", "--can", "udp_multicast:10.0.0.1", timeout=120)
    assert proc.returncode == 2 and "not a multicast address" in proc.stderr and "Traceback" not in proc.stderr


def vcan0() -> str | None:
    """Bring up vcan0 where the kernel can; else why not."""
    if subprocess.run(["ip", "link", "show", "vcan0"], capture_output=True).returncode != 0:
        add = subprocess.run(["ip", "link", "add", "dev", "vcan0", "type", "vcan"], capture_output=True, text=True)
        if add.returncode != 0:
            return (f"no kernel CAN on this host: `ip link add dev vcan0 type vcan` failed "
                    f"({(add.stderr or add.stdout).strip()}); load the vcan module (modprobe vcan) to run this test")
    up = subprocess.run(["ip", "link", "set", "up", "vcan0"], capture_output=True, text=True)
    if up.returncode != 0:
        return f"vcan0 exists but cannot be brought up: {(up.stderr or up.stdout).strip()}"
    return None


def test_a_stock_python_can_program_drives_the_arm_over_socketcan_vcan0(tmp_path):
    problem = vcan0()
    if problem:
        pytest.skip(problem)
    srv = ServerProcess(robot="hydrolek", can="socketcan:vcan0", tmp_path=tmp_path)
    try:
        check_the_arm_was_driven(srv, run_stock_client({"interface": "socketcan", "channel": "vcan0"}))
    finally:
        srv.stop()
