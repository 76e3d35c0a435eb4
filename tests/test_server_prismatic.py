"""A rig with a prismatic joint and a direct-acting cylinder behind the HIL service, unchanged: CAN
commands move it, feedback carries metres (the DBC says so), REST reports the same position."""

import time

import can
import pytest

from hil_server.can import dbc as D
from hil_server.service import HilService, ServiceConfig
from sim_core.model.spec import load_robot

from server_helpers import ROOT

pytestmark = pytest.mark.realtime

LIFT = ROOT / "tests" / "data" / "lift" / "robot.toml"


@pytest.fixture(scope="module")
def lift_service(tmp_path_factory):
    svc = HilService(ServiceConfig(robot=str(LIFT), can="virtual:hil_lift", viewer_port=None, watchdog_ms=200.0,
                                   feedback_rate_hz=100.0, recordings_dir=str(tmp_path_factory.mktemp("rec"))))
    svc.start_transports()
    yield svc
    svc.close()


def test_can_lifts_the_carriage_and_feedback_is_in_metres(lift_service):
    svc = lift_service
    db = D.load_database_for(load_robot(LIFT))
    cmd = db.get_message_by_name("ValveCommand_lift")
    fb = db.get_message_by_name("JointFeedback_lift")
    assert {s.name: s.unit for s in fb.signals}["angle"] == "m"
    bus = can.Bus(interface="virtual", channel="hil_lift", receive_own_messages=False)
    try:
        x0 = svc.documents.state()["joints"]["lift"]["angle"]
        frames = []
        for k in range(50):     # 0.5 s at 100 Hz, +5 V: the carriage rises
            bus.send(can.Message(arbitration_id=cmd.frame_id, data=cmd.encode({"voltage": 5.0, "counter": k}),
                                 is_extended_id=False))
            end = time.monotonic() + 0.01
            while time.monotonic() < end:
                m = bus.recv(0.005)
                if m is not None:
                    frames.append(m)
        st = svc.documents.state()["joints"]["lift"]
        assert 0.005 < st["angle"] - x0 < 0.2        # m: rising at a few cm/s, not radians
        fbs = [fb.decode(m.data) for m in frames if m.arbitration_id == fb.frame_id]
        assert len(fbs) >= 20 and fbs[-1]["angle"] == pytest.approx(st["angle"], abs=0.005)
    finally:
        bus.shutdown()
