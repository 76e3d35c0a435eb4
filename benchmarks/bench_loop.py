"""HIL loop timing under load (issue 3 targets: p99 lateness <= 100 us while serving 500 REST
requests/s and 1 kHz of CAN each way; overruns no more frequent than a bare busy-wait loop on the
same machine in the same run, ratio <= 1.5).

    .venv/bin/python benchmarks/bench_loop.py [--duration S] [--robot R] [--json]
"""

import argparse
import json

from hil_server.bench_loop import run


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=10.0, help="seconds per phase (bare, loaded, bare)")
    ap.add_argument("--robot", default="hydrolek")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    res = run(args.duration, args.robot)["loop"]
    if args.json:
        print(json.dumps(res, indent=2))
        return
    lat = res["lateness_us"]
    print(f"loop at {res['rate_hz']:.0f} Hz, {args.robot}, {res['loaded_seconds']:.0f} s loaded "
          f"({'SCHED_FIFO' if res['realtime_priority'] else 'normal priority'}: {res['realtime_note']})")
    print(f"  lateness p50 {lat['p50']:.1f} us  p99 {lat['p99']:.1f} us (target <= 100)  p99.9 {lat['p999']:.0f} us  max {lat['max']:.0f} us")
    print(f"  overruns {res['overruns']} = {res['overruns_per_10k_ticks']:.2f} per 10k ticks; bare loop "
          f"{res['bare_loop_overruns_per_10k_ticks']:.2f} per 10k; ratio {res['overrun_ratio_to_bare_loop']:.2f} (target <= 1.5)")
    r, c = res["rest_load"], res["can_load"]
    print(f"  REST {r['rps']:.0f} req/s (p50 {r['p50_ms']:.1f} ms, p99 {r['p99_ms']:.1f} ms, {r['errors']} errors); "
          f"CAN {c['tx_fps']:.0f} frames/s in, {c['rx_fps']:.0f} frames/s out")


if __name__ == "__main__":
    main()
