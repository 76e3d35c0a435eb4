"""The reference solver's cost: Radau pieces carrying the last step size and Jacobian against a fresh
solver per piece, on the physics tests' PRBS, measured in this run.

``solve_reference(method="Radau")`` restarts Radau at every command breakpoint and starts each piece
from the previous one's step size and Jacobian; passing scipy's ``Radau`` class instead of the name
goes through ``solve_ivp``, a fresh solver per piece (the reference before 2026-11-30). Printed per
robot: seconds of each, their ratio, and the largest difference of the joint positions (rad).

    .venv/bin/python benchmarks/bench_reference.py [--duration S] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from scipy.integrate import Radau

from sim_core.bench import prbs_all_joints
from sim_core.plant import Plant
from sim_core.reference import solve_reference


def run(robot: str, duration: float, rtol: float = 1e-9) -> dict:
    plant = Plant.from_robot(robot)
    t, U = prbs_all_joints(plant.spec, 2.0, amplitude=5.0, seed=11)     # the physics tests' PRBS
    n = int(np.searchsorted(t, duration)) + 1
    t, U = t[:n], U[:n]
    solve_reference(plant.create_context(), t[:3], U[:3], method="Radau", rtol=rtol)   # compiled and loaded
    out = {}
    for name, method in (("carried", "Radau"), ("fresh", Radau)):
        t0 = time.perf_counter()
        q, _ = solve_reference(plant.create_context(), t, U, method=method, rtol=rtol)
        out[name] = (time.perf_counter() - t0, q)
    return {"robot": robot, "seconds_simulated": float(t[-1] - t[0]), "carried_s": out["carried"][0],
            "fresh_s": out["fresh"][0], "ratio_fresh_to_carried": out["fresh"][0] / out["carried"][0],
            "max_position_difference_rad": float(np.max(np.abs(out["carried"][1] - out["fresh"][1])))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=0.4, help="seconds of the PRBS (default 0.4)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = [run(r, args.duration) for r in ("hydrolek", "harvester")]
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print(f"{'robot':10} {'carried s':>10} {'fresh s':>10} {'ratio':>7} {'max |dq| rad':>13}")
    for r in rows:
        print(f"{r['robot']:10} {r['carried_s']:10.2f} {r['fresh_s']:10.2f} {r['ratio_fresh_to_carried']:7.2f} "
              f"{r['max_position_difference_rad']:13.1e}")


if __name__ == "__main__":
    main()
