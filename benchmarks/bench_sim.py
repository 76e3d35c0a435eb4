"""Simulator speed: real-time factor at a 1 kHz output rate, us per output step, and the ratio to a
variable-step reference solver (scipy LSODA) of the same model at equal accuracy, all measured in
this run. Targets (issue 2): RTF >= 100 hydrolek, >= 50 mars_nd, >= 100 harvester.

    .venv/bin/python benchmarks/bench_sim.py [--duration S] [--json]
"""

import argparse
import json

from sim_core.bench import run_bench

TARGET_RTF = {"hydrolek": 100.0, "mars_nd": 50.0, "harvester": 100.0}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    res = run_bench(list(TARGET_RTF), duration=args.duration)
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


if __name__ == "__main__":
    main()
