"""The controller process: runs one scenario's controller against ``hydrohil serve`` over CAN only.

    python -m controllers.client --scenario stick --robot harvester --port 29536 --mode lockstep --out trace.npz

It loads the robot's identified model (the spec, with the same ``--params`` file the emulator runs)
for its feedforward and kinematics, opens python-can's socketcand client with the shipped DBC, runs
the control loop and writes the trace (``.npz``); a one-line JSON summary goes to stdout.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m controllers.client", description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", required=True)
    p.add_argument("--variant", default="", help="comparison controller (see scenarios.make_controller)")
    p.add_argument("--robot", required=True)
    p.add_argument("--port", type=int, required=True, help="socketcand port of hydrohil serve")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--mode", choices=["lockstep", "realtime"], default="lockstep")
    p.add_argument("--params", help="the parameter/effect file the emulator runs (the identified model)")
    p.add_argument("--duration", type=float, required=True, help="s")
    p.add_argument("--tick", type=float, default=1e-3, help="emulator tick (s) = 1/--rate")
    p.add_argument("--ticks", type=int, default=5, help="lockstep: emulator ticks per control period")
    p.add_argument("--feedback-rate", type=float, default=200.0, help="realtime: the emulator's feedback rate (Hz)")
    p.add_argument("--out", required=True, help="trace file (.npz)")
    args = p.parse_args(argv)
    logging.getLogger("can").setLevel(logging.ERROR)   # python-can's socketcand logs partial TCP reads as warnings

    from .plant_can import CanPlant
    from .plant_local import configured_spec
    from .scenarios import make_controller
    from .tracking import run_loop

    spec = configured_spec(args.robot, args.params)
    controller = make_controller(args.scenario, spec, args.variant)
    t0 = time.perf_counter()
    with CanPlant(args.port, args.robot, host=args.host, mode=args.mode, tick_s=args.tick, ticks=args.ticks,
                  feedback_rate_hz=args.feedback_rate) as plant:
        trace = run_loop(plant, controller, args.duration)
        emergencies = list(plant.emergencies)
    wall = time.perf_counter() - t0
    np.savez_compressed(args.out, **trace)
    watchdog = int(np.count_nonzero(trace["status"].astype(int) & 1))
    print(json.dumps({"scenario": args.scenario, "mode": args.mode, "steps": int(len(trace["t"])),
                      "plant_time_s": float(trace["t"][-1]), "wall_s": wall, "watchdog_samples": watchdog,
                      "emergencies": len(emergencies)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
