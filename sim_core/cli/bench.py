"""hydrohil bench: speed figures of the simulator (and of the HIL loop when installed)."""

import json


def register(sub):
    p = sub.add_parser("bench", help="measure real-time factor, us per step and the ratio to a reference solver")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--robots", nargs="+", metavar="ROBOT", help="default: all built-in robots")
    p.add_argument("--duration", type=float, default=10.0, help="simulated seconds per robot (default 10)")
    p.add_argument("--no-reference", action="store_true", help="skip the (slow) reference-solver comparison")
    p.add_argument("--no-plugins", action="store_true",
                   help="simulator only: skip benchmarks other packages add (the HIL loop under load, ~40 s)")
    p.set_defaults(func=run)


def run(args):
    from ..bench import run_bench

    res = run_bench(args.robots, duration=args.duration, reference=not args.no_reference, plugins=not args.no_plugins)
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    for name, r in res.items():
        if name == "loop":
            lat = r["lateness_us"]
            print(f"loop       1 kHz under {r['rest_load']['rps']:.0f} REST req/s and {r['can_load']['tx_fps']:.0f}/"
                  f"{r['can_load']['rx_fps']:.0f} CAN frames/s in/out: lateness p50 {lat['p50']:.1f} us, p99 {lat['p99']:.1f} us; "
                  f"overruns {r['overruns_per_10k_ticks']:.2f}/10k ticks vs bare loop {r['bare_loop_overruns_per_10k_ticks']:.2f} "
                  f"(ratio {r['overrun_ratio_to_bare_loop']:.2f})")
            continue
        if "real_time_factor" not in r:
            print(f"{name}: {json.dumps(r)}")
            continue
        line = (f"{name:<10} RTF {r['real_time_factor']:7.1f}  {r['us_per_output_step']:6.1f} us/step (batch)  "
                f"{r['us_per_step_call']:6.1f} us/step (per call)")
        if "ratio_to_reference" in r:
            ref = r["reference"]
            line += (f"  {r['ratio_to_reference']:6.0f}x faster than LSODA rtol {ref['rtol']:g} "
                     f"({ref['rms_error_mrad']:.3g} vs {ref['fixed_step_rms_error_mrad']:.3g} mrad)")
        print(line)
    return 0
