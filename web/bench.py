"""What drawing costs: CPU time per frame of the viewer's scene update, per robot, against viser's
``ViserUrdf.update_cfg`` on the same URDF. ``python -m web.bench [--frames N] [--json]``.

No plant and no browser: states are made up from the spec (joints swept through their ranges), a
real viser server holds the scene. Times are thread CPU time, so a busy machine does not inflate them.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

ROBOTS = ("hydrolek", "mars_nd", "harvester")


def _state(scene, q, p):
    joints = {j: {"pressure_a": p, "pressure_b": 0.8 * p} for j in scene.joint_names}
    return {"pose": dict(zip(scene.tree.dof_names, map(float, q))), "joints": joints}


def _cpu_per_call(fn, frames: int) -> float:
    c0 = time.thread_time()
    for k in range(frames):
        fn(k)
    return (time.thread_time() - c0) / frames * 1e3


def bench_robot(server, robot: str, frames: int) -> dict:
    from viser.extras import ViserUrdf

    from sim_core.model.spec import load_robot

    from .scene import ArmScene

    spec = load_robot(robot)
    server.scene.reset()
    scene = ArmScene(server, spec)
    q0, tree = scene.q0, scene.tree
    p = 0.5 * scene.actuators.p_supply
    step = 1e-3  # rad per frame: every moved joint is re-sent
    out = {"robot": robot, "bodies": tree.n, "actuator_instances": scene.actuators.n_instances}
    still = _state(scene, q0, p)
    scene.update(still)
    out["static_ms"] = _cpu_per_call(lambda k: scene.update(still), frames)

    def one(k):
        q = q0.copy()
        q[0] += step * (k + 1)
        scene.update(_state(scene, q, p))

    def all_(k):
        scene.update(_state(scene, q0 + step * (k + 1), p))

    out["one_joint_moving_ms"] = _cpu_per_call(one, frames)
    out["all_joints_moving_ms"] = _cpu_per_call(all_, frames)
    server.scene.reset()
    urdf = ViserUrdf(server, spec.urdf_path, root_node_name="/urdf")
    names = urdf.get_actuated_joint_names()
    out["viser_urdf_update_cfg_ms"] = _cpu_per_call(lambda k: urdf.update_cfg(np.full(len(names), step * (k + 1))),
                                                    frames)
    server.scene.reset()
    return out


def main(argv=None) -> int:
    import viser

    ap = argparse.ArgumentParser(prog="python -m web.bench", description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        rows = [bench_robot(server, r, args.frames) for r in ROBOTS]
    finally:
        server.stop()
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print("CPU ms per frame (scene update; the viewer draws at 40 Hz)")
    print(f"{'robot':<10} {'bodies':>6} {'static':>7} {'1 moving':>9} {'all moving':>11} {'ViserUrdf':>10}")
    for r in rows:
        print(f"{r['robot']:<10} {r['bodies']:>6} {r['static_ms']:>7.3f} {r['one_joint_moving_ms']:>9.3f} "
              f"{r['all_joints_moving_ms']:>11.3f} {r['viser_urdf_update_cfg_ms']:>10.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
