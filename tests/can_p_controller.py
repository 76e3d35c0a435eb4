"""A minimal external controller: holds one joint at a setpoint over CAN in lockstep (test helper).

Runs as its own process and speaks only CAN through python-can's stock socketcand client, with the
emulator's DBC: per tick it reads JointFeedback, sends ValveCommand, then SYNC, and waits for the
next feedback. Prints a JSON summary (final angle, trajectory digest).
"""

import hashlib
import json
import sys
import time

import can
import cantools


def main(port: int, dbc: str, joint: str, target: float, ticks: int, kp: float) -> None:
    db = cantools.database.load_file(dbc)
    cmd = db.get_message_by_name(f"ValveCommand_{joint}")
    fb = db.get_message_by_name(f"JointFeedback_{joint}")
    sync = db.get_message_by_name("Sync")
    bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="vcan0")
    angles = []
    angle = None
    counter = None
    # first feedback: ask for one tick
    bus.send(can.Message(arbitration_id=sync.frame_id, data=sync.encode({"counter": 0}), is_extended_id=False))
    for k in range(ticks + 1):
        deadline = time.monotonic() + 5.0
        while True:
            m = bus.recv(max(0.0, deadline - time.monotonic()))
            if m is None or time.monotonic() > deadline:
                raise SystemExit(f"tick {k}: no new feedback of {joint} within 5 s")
            if m.arbitration_id == fb.frame_id:
                d = fb.decode(m.data)
                if d["counter"] != counter:
                    counter = d["counter"]
                    angle = d["angle"]
                    break
        angles.append(angle)
        if k == ticks:
            break
        u = max(-10.0, min(10.0, kp * (target - angle)))
        bus.send(can.Message(arbitration_id=cmd.frame_id, data=cmd.encode({"voltage": u, "counter": k & 255}),
                             is_extended_id=False))
        bus.send(can.Message(arbitration_id=sync.frame_id, data=sync.encode({"counter": (k + 1) & 255}),
                             is_extended_id=False))
    bus.shutdown()
    digest = hashlib.sha256(json.dumps([round(a, 4) for a in angles]).encode()).hexdigest()
    print(json.dumps({"final": angles[-1], "first": angles[0], "digest": digest, "n": len(angles)}))


if __name__ == "__main__":
    main(int(sys.argv[1]), sys.argv[2], sys.argv[3], float(sys.argv[4]), int(sys.argv[5]), float(sys.argv[6]))
