"""Simulator speed, all measured in this run:

* real-time factor at a 1 kHz output rate, us per output step, and the ratio to a variable-step
  reference solver (scipy LSODA) of the same model at equal accuracy. Targets: RTF >= 100 hydrolek,
  >= 50 mars_nd, >= 100 harvester;
* each robot's full plant (us per simulated ms) against MuJoCo's ``mj_step`` of the bare HydroLek
  arm (its URDF, contacts off, 1 ms step): goal <= 2.0x for HydroLek (MuJoCo comes with the
  ``bench`` extra: ``pip install -e .[bench]``; without it the column is left out);
* a jittered 200 Hz time grid (+-10 % per step) against a regular one of the same length: the
  command chain's exact discretisation must not make jitter expensive (goal ratio <= 1.2).

    .venv/bin/python benchmarks/bench_sim.py [--duration S] [--json]
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np

from sim_core.bench import prbs_all_joints, run_bench
from sim_core.plant import Plant
from sim_core.simulator import Simulator

HYDROLEK_URDF = Path(__file__).resolve().parent.parent / "sim_core" / "robots" / "hydrolek" / "hydrolek.urdf"


def mujoco_us_per_ms(steps: int = 20000, repeats: int = 5) -> float | None:
    """MuJoCo mj_step of the bare HydroLek arm at a 1 ms step: us per step (fastest of ``repeats``)."""
    try:
        import mujoco
    except ImportError:
        return None
    m = mujoco.MjModel.from_xml_path(str(HYDROLEK_URDF))
    m.opt.timestep = 1e-3
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    d = mujoco.MjData(m)
    best = float("inf")
    for _ in range(repeats):
        mujoco.mj_resetData(m, d)
        t0 = time.perf_counter()
        for _ in range(steps):
            mujoco.mj_step(m, d)
        best = min(best, (time.perf_counter() - t0) / steps * 1e6)
    return best


def plant_us_per_ms(robot: str, duration: float, repeats: int = 5, settings: dict | None = None) -> float:
    """The full plant on a 1 kHz grid: us per simulated ms (fastest of ``repeats``); ``settings``:
    {parameter path: value} changed from the robot's spec."""
    plant = Plant.from_robot(robot)
    spec = plant.spec.copy()
    for path, value in (settings or {}).items():
        spec.set(path, value)
    t, U = prbs_all_joints(spec, duration, rate=1000.0, amplitude=3.0, seed=1)
    Simulator(plant.create_context(spec)).run(t[:50], U[:50])     # compile outside the timing
    best = float("inf")
    for _ in range(repeats):
        sim = Simulator(plant.create_context(spec))
        t0 = time.perf_counter()
        sim.run(t, U)
        best = min(best, (time.perf_counter() - t0) / (duration * 1e3) * 1e6)
    return best


def jitter_ratio(duration: float, repeats: int = 5) -> dict:
    """HydroLek on a 200 Hz grid, regular and jittered (+-10 % per step, same length): fastest runs."""
    plant = Plant.from_robot("hydrolek")
    t, U = prbs_all_joints(plant.spec, duration, rate=200.0, amplitude=3.0, seed=1)
    tj = t + np.random.default_rng(0).uniform(-0.1, 0.1, t.size) / 200.0
    tj[0] = 0.0
    best = {"regular": float("inf"), "jittered": float("inf")}
    for _ in range(repeats):
        for name, grid in (("regular", t), ("jittered", tj)):
            sim = Simulator(plant.create_context())
            t0 = time.perf_counter()
            sim.run(grid, U)
            best[name] = min(best[name], time.perf_counter() - t0)
    return {"regular_s": best["regular"], "jittered_s": best["jittered"],
            "ratio": best["jittered"] / best["regular"]}

TARGET_RTF = {"hydrolek": 100.0, "mars_nd": 50.0, "harvester": 100.0}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    res = run_bench(list(TARGET_RTF), duration=args.duration)
    mj = mujoco_us_per_ms()
    for name in TARGET_RTF:
        us = plant_us_per_ms(name, min(args.duration, 5.0))
        res[name]["us_per_simulated_ms"] = us
        res[name]["ratio_to_mujoco"] = None if mj is None else us / mj
    res["mujoco_bare_hydrolek_us_per_ms"] = mj
    kept = plant_us_per_ms("hydrolek", min(args.duration, 5.0), settings={"integrator.jacobian_tolerance": 1e-4})
    res["hydrolek_factor_kept_us_per_ms"] = kept
    res["jitter"] = jitter_ratio(min(args.duration, 10.0))
    if args.json:
        print(json.dumps(res, indent=2))
        return
    print(f"{'robot':<10} {'RTF':>7} {'target':>7} {'us/step':>8} {'us/call':>8} {'LSODA us/step':>14} {'ratio':>7}  accuracy (mrad RMS)")
    for name, target in TARGET_RTF.items():
        r = res[name]
        ref = r["reference"]
        print(f"{name:<10} {r['real_time_factor']:7.1f} {target:7.0f} {r['us_per_output_step']:8.2f} "
              f"{r['us_per_step_call']:8.2f} {ref['us_per_output_step']:14.1f} {r['ratio_to_reference']:7.0f}  "
              f"kernel {ref['fixed_step_rms_error_mrad']:.3g}, LSODA rtol {ref['rtol']:g}: {ref['rms_error_mrad']:.3g}")
    print()
    if mj is None:
        print("MuJoCo not installed (pip install -e .[bench]): no ratio to mj_step")
    else:
        print(f"MuJoCo mj_step, bare HydroLek arm, 1 ms step: {mj:.2f} us per simulated ms")
        for name in TARGET_RTF:
            r = res[name]
            goal = "  (goal <= 2.0)" if name == "hydrolek" else ""
            print(f"  {name:<10} full plant {r['us_per_simulated_ms']:7.2f} us/ms  ratio {r['ratio_to_mujoco']:5.2f}x{goal}")
        print(f"  hydrolek with integrator.jacobian_tolerance = 1e-4 (factor kept between refreshes): "
              f"{kept:.2f} us/ms  ratio {kept / mj:5.2f}x")
    j = res["jitter"]
    print(f"jittered vs regular 200 Hz grid (HydroLek): {j['jittered_s'] * 1e3:.1f} ms vs {j['regular_s'] * 1e3:.1f} ms, "
          f"ratio {j['ratio']:.2f} (goal <= 1.2)")


if __name__ == "__main__":
    main()
