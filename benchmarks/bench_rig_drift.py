"""A rig that changes while it is logged: a load picked up half way, the valve passing more as the oil
warms up, a supply that sags. One model of the rig does not fit the whole record; calibrated again
on its later part, it fits that part (``sim_core/identification/parameter_drift.py``).

Each case: ``rig new TEMPLATE`` -> the tests' closed-loop generator (``tests/rig_records.py``, the
rig's valve flow x1.1 and supply x0.9 against its spec, start off, jittered timestamps) with the
truth changed during the record -> ``hydrohil diagnose`` with the import options. The reference in
the same run is the record of an unchanged rig (``none``), which must read
``no_significant_discrepancy``. Printed per case: the verdict, what was named, whether the rig is
said to change and which parameters moved (first part -> later part, in combined standard errors).
A changed rig should read ``unexplained_discrepancy`` with the change said, never a named effect.

    .venv/bin/python benchmarks/bench_rig_drift.py [--seeds 3,4,5] [--template boom|cylinder|rotary]
        [--changes none,load,flow,supply] [--size 0.5,0.15,-0.15]

``load``: the payload the rig's spec carries (boom 40 kg, cylinder 100 kg, rotary 5 kg) grows by
SIZE of itself at 30 s; ``flow``: the valve's flow gain rises linearly by SIZE over the minute;
``supply``: the supply pressure changes linearly by SIZE. About 30 s per case on this 2-core VM.
"""

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from rig_records import closed_loop_record, write_headerless  # noqa: E402

from sim_core.model.spec import load_robot  # noqa: E402

DURATION_S = 60.0


def cli(*args) -> None:
    p = subprocess.run([sys.executable, "-m", "sim_core.cli", *map(str, args)], capture_output=True, text=True, cwd=ROOT)
    if p.returncode:
        raise RuntimeError(p.stderr.strip()[-400:])


def change(kind: str, joint: str, load_kg: float, size: float):
    """The generator's ``during`` hook for one kind of change, and the payload the truth starts with."""
    if kind == "none":
        return None
    held: dict = {}
    if kind == "load":
        def during(ctx, t):
            mass = load_kg * (1.0 if t < 0.5 * DURATION_S else 1.0 + size)
            if held.get("mass") != mass:
                ctx.enable_effect("payload", joint, mass=mass)
                held["mass"] = mass
        return during
    path = {"flow": f"joints.{joint}.valve.rated_flow", "supply": "supply.pressure"}[kind]

    def during(ctx, t):
        step = int(t * 2.0)                    # set twice a second: each set lowers the model again
        if held.get("step") != step:
            held.setdefault("start", float(ctx.get_parameter(path)))
            ctx.set_parameter(path, held["start"] * (1.0 + size * t / DURATION_S))
            held["step"] = step
    return during


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="3,4,5")
    ap.add_argument("--template", default="boom", help="the rig: a `hydrohil rig new` template")
    ap.add_argument("--changes", default="none,load,flow,supply")
    ap.add_argument("--size", default="0.5,0.15,-0.15", help="per change but none: the load's added share, the "
                                                             "flow's and the supply's change over the record")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench_drift_"))
    cli("rig", "new", args.template, "--out", work / "rig")
    spec = load_robot(work / "rig")
    joint = spec.joint_names[0]
    load_kg = next(float(e.params["mass"]) for e in spec.effects if e.name == "payload" and e.joint == joint)
    read = ["--no-header", "--column", "time=0", "--column", f"q_{joint}=1:sensor_volts", "--column", f"u_{joint}=2"]
    kinds = args.changes.split(",")
    sizes = dict(zip([k for k in kinds if k != "none"], map(float, args.size.split(","))))
    results = []        # (change, verdict, change said, effect named) per case
    for seed in map(int, args.seeds.split(",")):
        for kind in kinds:
            rows, _ = closed_loop_record(work / "rig", hidden=None, seed=seed, start_offset=0.03,
                                         off={f"joints.{joint}.valve.rated_flow": 1.1, "supply.pressure": 0.9},
                                         during=change(kind, joint, load_kg, sizes.get(kind, 0.0)), duration=DURATION_S)
            write_headerless(rows, work / "log.csv")
            cli("diagnose", "--robot", work / "rig", work / "log.csv", *read, "--report", work / "rep", "--quiet")
            d = json.loads((work / "rep" / "diagnosis.json").read_text())
            named = ", ".join(s["effect"] + (" (ambiguous)" if s.get("ambiguous") else "") for s in d["selected"])
            drift = (d.get("unexplained") or {}).get("parameter_drift") or {}
            moved = "; ".join(f"{m['parameter'].split('.', 1)[1]} {m['first']:.4g} -> {m['last']:.4g} ({m['sigmas']:.0f} sigma)"
                              for m in drift.get("moved", []))
            if drift.get("jointly"):
                j = drift["jointly"]
                moved = f"together, chi-square {j['chi2']:.0f} on {j['dof']} (level {j['level']:.1f}): {moved}"
            print(f"seed {seed} {kind:6s} {d['verdict']:27s} {named or '-':24s} "
                  f"{'said: ' + moved if drift else 'not said'}"
                  + (f" (later part {drift['score_before']:.1f} -> {drift['score_after']:.1f}, ceiling {drift['ceiling']:.1f})"
                     if drift else ""), flush=True)
            results.append((kind, d["verdict"], bool(drift), bool(d["selected"])))
    changed = [r for r in results if r[0] != "none"]
    unchanged = [r for r in results if r[0] == "none"]
    print(f"\nchanged rigs ({len(changed)} cases): unexplained_discrepancy "
          f"{sum(r[1] == 'unexplained_discrepancy' for r in changed)}, the change said {sum(r[2] for r in changed)}, "
          f"a bank effect named {sum(r[3] for r in changed)} (want 0); unchanged: "
          f"{sum(r[1] != 'no_significant_discrepancy' for r in unchanged)} of {len(unchanged)} not clean (want 0)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
