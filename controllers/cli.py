"""hydrohil reproduce: run the closed-loop scenarios through the emulator and write the figures.

Each scenario starts its own ``hydrohil serve`` subprocess on free ports, runs the reference
controller as a separate process talking CAN (socketcand, the shipped DBC) and the same controller
in-process for the simulated comparison; metrics are printed and written to ``<out>/<scenario>.json``,
figures to ``<out>/*.png``.
"""

from __future__ import annotations

import json
import subprocess


SCENARIO_NAMES = ("stick", "cartesian", "mars_nd")   # = scenarios.SCENARIOS (kept light: no imports at start-up)


def register(sub):
    p = sub.add_parser("reproduce", help="closed-loop results of the papers through the emulator (controllers over CAN)")
    p.add_argument("--scenario", default="all", help=f"one of {', '.join(SCENARIO_NAMES)}, or all (default)")
    p.add_argument("--out", default="results", help="directory for figures, traces and metrics (default results/)")
    p.add_argument("--mode", default="lockstep", help="emulator mode: lockstep (deterministic) or realtime")
    p.add_argument("--duration", type=float, help="override the scenario's duration (s)")
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")
    p.set_defaults(func=run)


def _fmt(name: str, m: dict) -> list[str]:
    if name == "stick":
        e, s, d, f = m["emulated"], m["simulated"], m["emulated_vs_simulated"], m["feedforward"]
        lines = [f"  stick tracking error (emulated): rms {e['rms_error_rad'] * 1e3:.2f} mrad, max {e['max_error_rad'] * 1e3:.2f} mrad "
                 f"for a {2 * m['amplitude_rad']:.2f} rad peak-to-peak, {m['period_s']:g} s sinusoid",
                 f"  simulated: rms {s['rms_error_rad'] * 1e3:.2f} mrad; emulated - simulated error: rms "
                 f"{d['rms_difference_rad'] * 1e3:.3f} mrad ({100 * d['relative_rms']:.1f} % of the error)"]
        if "emulated_vs_simulated_quantized" in m:
            lines.append(f"  simulated with CAN quantisation vs emulated: max difference "
                         f"{m['emulated_vs_simulated_quantized']['max_difference_rad']:.3g} rad")
        lines.append(f"  feedforward vs PID command: rms difference {f['rms_difference_away_from_reversals_v']:.3f} V "
                     f"({100 * f['relative_difference_away_from_reversals']:.1f} %) away from spool reversals, "
                     f"{f['rms_difference_at_reversals_v']:.2f} V (max {f['max_difference_at_reversals_v']:.2f} V) around them")
        return lines
    if name == "cartesian":
        lines = []
        for run, r in m.items():
            if run in ("run", "figures"):
                continue
            lines.append(f"  {run:<10} path {r['path_length_m']:.2f} m, rms error {100 * r['rms_error_m']:.2f} cm "
                         f"({100 * r['relative_error']:.2f} %), max {100 * r['max_error_m']:.1f} cm; joint rms "
                         + ", ".join(f"{j} {v * 1e3:.1f}" for j, v in r["rms_joint_error_rad"].items()) + " mrad")
        return lines
    if name == "mars_nd":
        lines = []
        for run, r in m.items():
            if not isinstance(r, dict) or "holds" not in r:
                continue
            lines.append(f"  {run:<10} settled holds {r['settled_holds']}/{r['n_holds']}, holds with valve activity in "
                         f"the last second {r['holds_with_valve_activity']}, max final error "
                         f"{r['max_final_error_rad'] * 1e3:.2f} mrad, largest angle peak-to-peak {r['max_peak_to_peak_rad'] * 1e3:.2f} mrad")
        return lines
    return []


def run(args) -> int:
    from sim_core.cli import CliError

    from .experiment import run_scenario
    from .scenarios import SCENARIOS

    names = list(SCENARIOS) if args.scenario == "all" else [args.scenario]
    if args.scenario != "all" and args.scenario not in SCENARIOS:
        raise CliError(f"--scenario {args.scenario!r}: one of {', '.join(SCENARIOS)}, all")
    if args.mode not in ("lockstep", "realtime"):
        raise CliError(f"--mode {args.mode!r}: lockstep or realtime")
    if args.duration is not None and not args.duration > 0.0:
        raise CliError(f"--duration {args.duration:g}: must be > 0 s")
    results = {}
    for name in names:
        try:
            m = run_scenario(name, args.out, mode=args.mode, duration=args.duration)
        except (RuntimeError, TimeoutError, OSError, subprocess.TimeoutExpired) as exc:
            raise CliError(f"scenario {name}: {exc}") from None
        results[name] = m
        if not args.json:
            r = m["run"]
            print(f"{name}: {r['title']} [{r['robot']}, {r['mode']}, {r['duration_s']:g} s, "
                  f"{r['controller']['wall_s']:.1f} s wall over CAN]")
            for line in _fmt(name, m):
                print(line)
            for f in m.get("figures", []):
                print(f"  figure: {f}")
    if args.json:
        print(json.dumps(results, indent=2, default=float))
    return 0
