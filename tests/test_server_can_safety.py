"""CAN conventions a real controller expects: a flood on one id cannot starve valid commands (per-id
budgets), and the ValveCommand alive counter is checked (stuck or jumping counters counted; past the
limit the frames count as lost and the watchdog puts the valve in its safe state)."""

import json
import socket
import subprocess
import sys
import threading
import time

import can
import cantools
import pytest

from hil_server.can import dbc as D
from hil_server.service import HilService, ServiceConfig

from server_helpers import ServerProcess

pytestmark = pytest.mark.realtime

CONTROLLER = r"""
import json, sys, time, logging, can, cantools
logging.getLogger("can").setLevel(logging.ERROR)
port, dbc, seconds = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
db = cantools.database.load_file(dbc)
cmd, emcy = db.get_message_by_name("ValveCommand_j2"), db.get_message_by_name("Emergency")
bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="vcan0", tcp_tune=True)
sent, emcys, last = 0, [], 0.0
start = time.perf_counter()
while time.perf_counter() - start < seconds:
    last = round(2.0 + (sent % 200) / 100.0, 3)          # a ramp: every frame differs from the one before
    bus.send(can.Message(arbitration_id=cmd.frame_id, data=cmd.encode({"voltage": last, "counter": sent & 0xFF}),
                         is_extended_id=False))
    sent += 1
    nxt = start + sent / 1000.0                         # 1 kHz
    while True:
        m = bus.recv(max(0.0, nxt - time.perf_counter()))
        if m is not None and m.arbitration_id == emcy.frame_id:
            emcys.append(emcy.decode(m.data, decode_choices=False))
        if m is None or time.perf_counter() >= nxt:
            break
end = time.perf_counter() + 1.0     # keep reading before closing: a socket closed with unread data
while time.perf_counter() < end:     # resets the connection, and the server would lose our last frames
    bus.recv(0.05)
bus.shutdown()
print(json.dumps({"sent": sent, "last": last, "emcy": emcys}))
"""


def flood(port: int, stop: threading.Event, sent: list) -> None:
    """A babbling node on unknown id 0x5A5, as fast as TCP takes it (raw socketcand protocol)."""
    s = socket.create_connection(("127.0.0.1", port))
    s.settimeout(5)
    s.recv(64)
    s.sendall(b"< open vcan0 >")
    s.recv(64)
    s.sendall(b"< rawmode >")
    s.recv(64)
    frame = b"< send 5A5 8 FF FF FF FF FF FF FF FF >"
    chunk = frame * 2000
    s.setblocking(False)
    s.settimeout(0.5)
    while not stop.is_set():
        try:
            s.sendall(chunk)
            sent[0] += 2000
        except (TimeoutError, BlockingIOError):
            continue
    s.close()


def counters(c) -> dict:
    h = c.get("/api/v1/health").json()
    return {"frames": h["can"]["frames"], "trips": c.get("/api/v1/state").json()["loop"]["watchdog_trips"]}


def test_a_flood_on_an_unknown_id_cannot_starve_a_1khz_controller(tmp_path):
    srv = ServerProcess(robot="hydrolek", can="socketcand", tmp_path=tmp_path)
    stop, flooded = threading.Event(), [0]
    try:
        with srv.client() as c:
            before = counters(c)
            th = threading.Thread(target=flood, args=(srv.can_port, stop, flooded), daemon=True)
            th.start()
            time.sleep(0.5)
            out = subprocess.run([sys.executable, "-c", CONTROLLER, str(srv.can_port), str(D.dbc_path("hydrolek")), "3.0"],
                                 capture_output=True, text=True, timeout=120)
            stop.set()
            th.join(10)
            assert out.returncode == 0, out.stderr
            ctl = json.loads(out.stdout)
            after = counters(c)
            st = c.get("/api/v1/state").json()["joints"]["j2"]
        got = lambda k: after["frames"].get(f"rx.{k}", 0) - before["frames"].get(f"rx.{k}", 0)  # noqa: E731
        assert ctl["sent"] > 2000
        assert got("command") == ctl["sent"]                    # every valid command applied, none lost
        assert got("counter_jump") == got("counter_stuck") == 0
        # the watchdog never tripped while the controller ran (no EMCY on its bus); it trips once after
        # the controller stopped sending, as it should
        assert not [e for e in ctl["emcy"] if e["error_code"] == D.EMCY_TIMEOUT]
        assert after["trips"] - before["trips"] == 1
        assert st["requested_voltage"] == pytest.approx(ctl["last"], abs=1e-3)
        # the flood was real: beyond its id's budget, dropped (and said so) rather than processed
        assert flooded[0] > 60000 and got("flood_dropped") > 0 and got("unknown_id") > 0
        assert any(e["error_code"] == D.EMCY_CAN_OVERRUN for e in ctl["emcy"])
    finally:
        stop.set()
        srv.stop()


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    svc = HilService(ServiceConfig(robot="hydrolek", can="virtual:hil_alive", viewer_port=None, watchdog_ms=100.0,
                                   recordings_dir=str(tmp_path_factory.mktemp("rec"))))
    svc.start_transports()
    yield svc
    svc.close()


def test_the_alive_counter_is_checked(service):
    svc = service
    db = cantools.database.load_file(str(D.dbc_path("hydrolek")))
    cmd, emcy = db.get_message_by_name("ValveCommand_j4"), db.get_message_by_name("Emergency")
    bus = can.Bus(interface="virtual", channel="hil_alive", receive_own_messages=False)
    frames = []

    def send(volts, counter, wait=0.01):
        bus.send(can.Message(arbitration_id=cmd.frame_id, data=cmd.encode({"voltage": volts, "counter": counter}),
                             is_extended_id=False))
        end = time.monotonic() + wait
        while time.monotonic() < end:
            m = bus.recv(0.002)
            if m is not None:
                frames.append(m)

    def rx(kind):
        return svc.bridge.counters.get(("rx", kind), 0)

    def emcys(code):
        return [e for e in (emcy.decode(m.data, decode_choices=False) for m in frames if m.arbitration_id == emcy.frame_id)
                if e["error_code"] == code and e["joint"] == 3]

    def j4():
        return svc.documents.state()["joints"]["j4"]

    try:
        # a counter that steps by one: every frame applied
        for k in range(20):
            send(1.0 + 0.01 * k, (250 + k) & 0xFF)          # wraps 255 -> 0
        assert j4()["requested_voltage"] == pytest.approx(1.19) and rx("counter_jump") == 0
        # frames lost on the way: one jump, counted, the frame still applied
        send(1.5, (250 + 19 + 3) & 0xFF)
        assert rx("counter_jump") == 1 and j4()["requested_voltage"] == pytest.approx(1.5)
        stuck = (250 + 19 + 4) & 0xFF
        send(1.6, stuck)                                     # steps by one again: the error streak ends
        # a stuck counter (the sender's task hung, its CAN controller repeats the frame): the first
        # 3 repeats are tolerated, then the frames count as lost and the watchdog goes to neutral
        trips0 = svc.documents.loop_stats()["watchdog_trips"]
        for k in range(30):
            send(2.0 if k < 3 else 3.0, stuck)
        js = j4()
        assert rx("counter_stuck") == 30 and rx("counter_lost") == 27
        assert js["requested_voltage"] == pytest.approx(2.0)    # the lost frames' 3 V never arrived
        assert js["watchdog"] and js["command_voltage"] == 0.0  # safe state
        assert svc.documents.loop_stats()["watchdog_trips"] == trips0 + 1
        assert len(emcys(D.EMCY_ALIVE_COUNTER)) == 1 and emcys(D.EMCY_TIMEOUT)
        # the counter steps again: recovered at once
        send(-1.0, (stuck + 1) & 0xFF, wait=0.05)
        js = j4()
        assert not js["watchdog"] and js["command_voltage"] == pytest.approx(-1.0)
        assert any(e["fmi"] == D.FMI_NETWORK_DATA for e in emcys(D.EMCY_RESET))
    finally:
        bus.shutdown()
        svc.commands.write({3: 0.0}, 0.0)
