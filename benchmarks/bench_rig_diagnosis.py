"""How ``hydrohil diagnose`` does on a user's own rig, over more cases than its tests run: every
``rig new`` template x every hidden effect of the "Your own rig" checks (deadband, valve asymmetry,
Coulomb friction, leakage, delay), a valve null offset and a clean record, over several seeds.

Each case goes the user's way with the real commands: ``rig new TEMPLATE`` -> a record made in closed
loop by the tests' generator (``tests/rig_records.py``: P control around the rig with its nominal
parameters off, valve flow x1.2 and supply pressure x0.85 by default, start 5 % of the stroke off,
50 Hz, jittered timestamps, headerless CSV of time, sensor volts and command volts, no pressures)
-> ``hydrohil import`` -> ``hydrohil diagnose``. Printed per case: what was hidden, the verdict,
what was named, the parameter error (and, where the value is conditional on a parameter the
calibration held at nominal, the error once corrected with its elasticity to the truth's value of
it: a figure, not a score) and the seconds; then the share of cases right per effect and
overall (named alone, within 15 %; clean: ``no_significant_discrepancy``), the reference in the same
run being the clean records' false alarms. A wrong name that the report marks ambiguous with the
hidden effect as its runner-up is counted apart (the report then says what would decide).

    .venv/bin/python benchmarks/bench_rig_diagnosis.py [--templates cylinder,boom,rotary]
        [--effects deadband,valve_asymmetry,coulomb_friction,leakage,delay,valve_offset,none] [--seeds 1]
        [--first-seed 1] [--flow 1.2] [--supply 0.85] [--off PATH=FACTOR ...] [--rate 50] [--log-every 1] [--rig-set KNOB=VALUE ...] [--realistic]
        [--integral-time S] [--reference steps|sine] [--coulomb-share 0.06] [--measured supply,load,flow,sensor]
        [--json FILE]

About 25 s per case on this 2-core VM (21 cases per seed with the defaults).
"""

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))     # the record generator the tests use

from rig_records import closed_loop_record, logged_like_a_daq, measured, reference_steps, sine_reference, write_headerless  # noqa: E402

from sim_core.identification import conditional  # noqa: E402
from sim_core.identification.candidates import actuator_scales  # noqa: E402
from sim_core.model.spec import estimable, load_robot  # noqa: E402

TOLERANCE = 0.15


def hidden_params(effect: str, spec, joint: str, coulomb_share: float = 0.06) -> dict | None:
    """The hidden effect's parameters, sized to the rig (the checks' magnitudes); ``coulomb_share``:
    the Coulomb friction as a share of the actuator's full-pressure force or torque."""
    sc = actuator_scales(spec, joint)
    return {"deadband": {"width": 0.8}, "valve_asymmetry": {"ratio": 0.7}, "delay": {"delay": 0.06},
            "coulomb_friction": {"torque": coulomb_share * sc["torque"]},
            "leakage": {"internal": 0.04 * sc["q_full"] / spec.supply["pressure"]},
            "valve_offset": {"offset": 0.25}, "none": None}[effect]


def realistic_truth(spec, joint: str) -> tuple[tuple[str, dict], ...]:
    """Physics of a real rig the diagnosis is not asked to name: seal friction with a breakaway
    (Stribeck: static 4 %, sliding 2.5 % of the full-pressure force, falling over 1 % of the
    full-flow speed)."""
    sc = actuator_scales(spec, joint)
    speed = sc["q_full"] * spec.supply["pressure"] / sc["torque"]       # full flow over A x lever: m/s or rad/s
    return (("stribeck_friction", {"static_torque": 0.04 * sc["torque"], "coulomb_torque": 0.025 * sc["torque"],
                                   "stribeck_velocity": 0.01 * speed, "smoothing_velocity": 0.001 * speed}),)


def cli(*args) -> None:
    p = subprocess.run([sys.executable, "-m", "sim_core.cli", *map(str, args)], capture_output=True, text=True,
                       cwd=ROOT)
    if p.returncode:
        raise RuntimeError(f"hydrohil {' '.join(map(str, args[:2]))} failed: {p.stderr.strip()[-800:]}")


def diagnose_log(work: Path, rig: Path, joint: str) -> tuple[dict, float]:
    """``work/log.csv`` (headerless: time s, sensor volts, command V) through ``hydrohil import`` and
    ``hydrohil diagnose`` the user's way: (diagnosis.json, seconds for both)."""
    t0 = time.perf_counter()
    cli("import", work / "log.csv", "--robot", rig, "--out", work / "rec.csv", "--no-header",
        "--column", "time=0", "--column", f"q_{joint}=1:sensor_volts", "--column", f"u_{joint}=2")
    cli("diagnose", "--robot", rig, work / "rec.csv", "--report", work / "rep", "--quiet")
    return json.loads((work / "rep" / "diagnosis.json").read_text()), time.perf_counter() - t0


REFERENCES = {"steps": reference_steps, "sine": sine_reference}


def run_case(work: Path, template: str, effect: str, seed: int, flow: float, supply: float, log_every: int = 1,
             rig_set: tuple[str, ...] = (), realistic: bool = False, ti: float | None = None,
             reference: str = "steps", coulomb_share: float = 0.06, measured_keys: tuple[str, ...] = (),
             more_off: tuple[str, ...] = (), rate: float = 50.0) -> dict:
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    cli("rig", "new", template, "--out", work / "rig", *[a for s in rig_set for a in ("--set", s)])
    spec = load_robot(work / "rig")
    joint = spec.joint_names[0]
    i = spec.tree.index(spec.joint(joint).dof)
    span = float(spec.tree.upper[i] - spec.tree.lower[i])
    params = hidden_params(effect, spec, joint, coulomb_share)
    off = {f"joints.{joint}.valve.rated_flow": flow, "supply.pressure": supply}
    for item in more_off:       # PATH=FACTOR, {joint} and {actuator} filled in for this rig
        path, factor = item.split("=")
        off[path.format(joint=joint, actuator=spec.joint(joint).kind)] = float(factor)
    rows, _ = closed_loop_record(work / "rig", hidden=None if params is None else (effect, params), off=off,
                                 seed=seed, duration=60.0, start_offset=0.05 * span, log_every=log_every, rate=rate,
                                 extra=realistic_truth(spec, joint) if realistic else (), ti=ti,
                                 reference=REFERENCES[reference])
    if realistic:
        rows = logged_like_a_daq(rows, np.random.default_rng(1000 + seed), bits=12, dropouts=3)
    write_headerless(rows, work / "log.csv")
    rig = work / "rig"
    if measured_keys:           # the user measured these: the truth's values written in, held by calibration
        paths = {"supply": ["supply.pressure"], "flow": [f"joints.{joint}.valve.rated_flow"],
                 "load": [f"effects.payload.{joint}.mass"], "sensor": [f"joints.{joint}.sensor.{k}" for k in "AB"]}
        rig = work / "rig_measured"
        shutil.copytree(work / "rig", rig)
        measured(rig, {k: estimable(spec, k)[1] * off.get(k, 1.0) for name in measured_keys for k in paths[name]})
    d, seconds = diagnose_log(work, rig, joint)
    named = [s["effect"] for s in d["selected"]]
    # a wrong name the report itself marks ambiguous, with the hidden effect as its runner-up
    flagged = any(s.get("ambiguous") and (s.get("runner_up") or {}).get("effect") == effect for s in d["selected"])
    error = corrected = other_error = None
    if params:
        key = next(iter(params))
        hit = [s for s in d["selected"] if s["effect"] == effect]
        if hit:
            error = hit[0]["params"][key] / params[key] - 1.0
            # the value corrected with its elasticities to what the calibration held at nominal, given
            # the truth's values of those (the bench's factors; the rest of the truth is nominal)
            held = (hit[0].get("elasticity_to_held") or {}).get(key)
            if held:
                corrected = conditional.corrected(hit[0]["params"][key], held, off) / params[key] - 1.0
        right = named == [effect] and error is not None and abs(error) <= TOLERANCE
        other = hit[0].get("if_command_hold") if hit else None
        if other and key in other["params"]:     # the value with the command replayed the other way
            other_error = (other["replay"], other["params"][key] / params[key] - 1.0, other.get("score_points"))
    else:
        right = d["verdict"] == "no_significant_discrepancy"
    return {"template": template, "effect": effect, "seed": seed, "truth": params, "verdict": d["verdict"],
            "named": [(s["effect"], s["params"]) for s in d["selected"]], "error": error, "right": right,
            "error_given_true_held": corrected, "error_other_hold": other_error,
            "command_hold": (d["closed_loop_evidence"].get("command_hold") or {}).get("replay"),
            "ambiguous_with_truth": bool(params) and not right and flagged,
            "fit_before": d["baseline"]["fit"][joint],
            "fit_after": (d.get("extended") or {}).get("fit", {}).get(joint), "seconds": seconds}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--templates", default="cylinder,boom,rotary")
    ap.add_argument("--effects", default="deadband,valve_asymmetry,coulomb_friction,leakage,delay,valve_offset,none")
    ap.add_argument("--seeds", type=int, default=1, help="noise/excitation seeds per case (1..N)")
    ap.add_argument("--first-seed", type=int, default=1, help="start the seeds here (FIRST..FIRST+N-1)")
    ap.add_argument("--flow", type=float, default=1.2, help="the rig's valve flow against its spec (factor)")
    ap.add_argument("--supply", type=float, default=0.85, help="the rig's supply pressure against its spec (factor)")
    ap.add_argument("--off", action="append", default=[], metavar="PATH=FACTOR",
                    help="another parameter of the truth off its spec by this factor, e.g. fluid.bulk_modulus=0.7 or "
                         "joints.{joint}.{actuator}.viscous_friction=1.3 (repeatable)")
    ap.add_argument("--rate", type=float, default=50.0, metavar="HZ", help="the log's rate (default 50 Hz)")
    ap.add_argument("--log-every", type=int, default=1, metavar="M",
                    help="the rig's controller runs at M x the log's rate and the log keeps every M-th sample")
    ap.add_argument("--rig-set", action="append", default=[], metavar="KNOB=VALUE",
                    help="passed to 'rig new --set' (e.g. incline_deg=-90: a load hanging below the cylinder)")
    ap.add_argument("--realistic", action="store_true",
                    help="the truth has seal friction with a breakaway (Stribeck, out of the bank) and the log a 12-bit "
                         "converter and three wiper dropouts to 0 V")
    ap.add_argument("--integral-time", type=float, default=None, metavar="S",
                    help="the rig's controller is PI with this integral time (s; integral gain kp / S), not P")
    ap.add_argument("--reference", choices=list(REFERENCES), default="steps",
                    help="what the rig's controller tracks: operator-like steps with holds, or a slow sine (0.1-0.3 Hz)")
    ap.add_argument("--coulomb-share", type=float, default=0.06, metavar="SHARE",
                    help="the hidden Coulomb friction as a share of the full-pressure force (default 0.06)")
    ap.add_argument("--measured", default="", metavar="KEYS",
                    help="comma-separated, of supply, load, flow, sensor (its A and B): the user measured these, so the rig's robot.toml "
                         "says the truth's value and they leave its [estimated] table (held by calibration)")
    ap.add_argument("--json", metavar="FILE", help="also write the cases as JSON")
    args = ap.parse_args()
    measured_keys = tuple(k for k in args.measured.split(",") if k)
    unknown = set(measured_keys) - {"supply", "load", "flow", "sensor"}
    if unknown:
        ap.error(f"--measured: unknown {', '.join(sorted(unknown))}; known: supply, load, flow, sensor")
    tmp = Path(tempfile.mkdtemp(prefix="bench_rig_"))
    cases = []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        for template in args.templates.split(","):
            for effect in args.effects.split(","):
                try:
                    c = run_case(tmp / f"{template}_{effect}_{seed}", template, effect, seed, args.flow, args.supply,
                                 args.log_every, tuple(args.rig_set), args.realistic, args.integral_time,
                                 args.reference, args.coulomb_share, measured_keys, tuple(args.off), args.rate)
                except Exception as exc:  # a case that fails is a finding, not the end of the run
                    c = {"template": template, "effect": effect, "seed": seed, "right": False, "failed": str(exc)}
                cases.append(c)
                if "failed" in c:
                    print(f"{template:9s} {effect:17s} seed {seed}: FAILED {c['failed']}", flush=True)
                    continue
                err = "" if c["error"] is None else f" error {100 * c['error']:+.1f} %"
                if c.get("error_given_true_held") is not None:
                    err += f" ({100 * c['error_given_true_held']:+.1f} % corrected to the true held values)"
                if c.get("error_other_hold"):
                    how, e, pts = c["error_other_hold"]
                    err += f" ({100 * e:+.1f} % replayed {how}" + ("" if pts is None else f", {pts:+.2f} points") + ")"
                err += f"; command {c['command_hold']}" if c.get("command_hold") else ""
                named = ", ".join(f"{e} {', '.join(f'{k}={v:.4g}' for k, v in p.items())}" for e, p in c["named"]) or "-"
                after = "" if c["fit_after"] is None else f" -> {c['fit_after']:.1f}"
                amb = f" (ambiguous, runner-up {effect})" if c["ambiguous_with_truth"] else ""
                print(f"{template:9s} {effect:17s} seed {seed}: {'RIGHT' if c['right'] else 'wrong'}  {c['verdict']}: "
                      f"{named}{amb}{err}; fit {c['fit_before']:.1f}{after} %; {c['seconds']:.0f} s", flush=True)
    print(f"\nrig off nominal: valve flow x{args.flow:g}, supply x{args.supply:g}"
          + "".join(f", {o.replace('=', ' x')}" for o in args.off)
          + (f"; logged at {args.rate:g} Hz" if args.rate != 50.0 else "")
          + (f"; controller at {args.log_every} x the log's rate" if args.log_every > 1 else "")
          + (f"; rig new --set {' '.join(args.rig_set)}" if args.rig_set else "")
          + ("; realistic: Stribeck seal friction in the truth, 12-bit volts, 3 dropouts" if args.realistic else "")
          + (f"; PI control, integral time {args.integral_time:g} s" if args.integral_time else "")
          + ("; the set point a slow sine" if args.reference == "sine" else "")
          + (f"; Coulomb friction {args.coulomb_share:g} x the full-pressure force" if args.coulomb_share != 0.06 else "")
          + (f"; measured (held at the truth's values): {', '.join(measured_keys)}" if measured_keys else "")
          + "; right = named alone within "
          f"{100 * TOLERANCE:.0f} % (clean: no_significant_discrepancy)")
    for effect in args.effects.split(","):
        sel = [c for c in cases if c["effect"] == effect]
        amb = sum(c.get("ambiguous_with_truth", False) for c in sel)
        print(f"  {effect:17s} {sum(c['right'] for c in sel)}/{len(sel)} right"
              + (f", {amb} more named wrong but marked ambiguous with it as the runner-up" if amb else ""))
    hidden = [c for c in cases if c["effect"] != "none"]
    clean = [c for c in cases if c["effect"] == "none"]
    if hidden:
        print(f"  hidden effects named right: {100 * sum(c['right'] for c in hidden) / len(hidden):.0f} % of {len(hidden)}")
    if clean:
        print(f"  clean records with a false alarm: {100 * sum(not c['right'] for c in clean) / len(clean):.0f} % "
              f"of {len(clean)}")
    done = [c["seconds"] for c in cases if "seconds" in c]
    if done:
        print(f"  diagnose (import included): median {sorted(done)[len(done) // 2]:.0f} s, max {max(done):.0f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(cases, indent=1))
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
