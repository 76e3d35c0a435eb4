"""Speed of ``hydrohil diagnose`` on a 60 s, 200 Hz single-joint record with every candidate (issue 5:
<= 30 s on a 2-core machine; the later goal: <= 6 s with both cores). The record is made with the real commands (excite + simulate, a hidden
deadband on the HydroLek shoulder, and a clean record); the diagnosis and its report run as the CLI
does, in this process. Reference measured in the same run: one free-run simulation of the record at the default
integrator settings, so the figure also reads as "diagnose costs N simulations".

    .venv/bin/python benchmarks/bench_diagnose.py [--workers N] [--sequential] [--json] [--no-preload]

``--sequential`` also times one worker, to show the parallel speed-up. The machine's load average is
printed: other work on the machine slows every figure.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 30.0
GOAL_S = 6.0         # every candidate and the report, both cores of a 2-core machine
ROOT = Path(__file__).resolve().parent.parent


def cli(*args):
    subprocess.run([sys.executable, "-m", "sim_core.cli", *map(str, args)], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=0, help="0: CPU count")
    ap.add_argument("--sequential", action="store_true", help="also time one worker")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-preload", action="store_true",
                    help="import pyplot only when the report draws (to compare: the first record's figure pays it)")
    args = ap.parse_args()

    from sim_core.identification import diagnosis, report
    from sim_core.identification.record import load_record
    from sim_core.identification.simulation import Runner, model_spec
    from sim_core.model.spec import load_robot

    tmp = Path(tempfile.mkdtemp(prefix="bench_diagnose_"))
    cli("excite", "--robot", "hydrolek", "--joint", "j2", "--duration", 60, "--rate", 200, "--seed", 7, "--out", tmp / "in.csv")
    records = {
        "deadband": ["--effect", "deadband:joint=j2,width=0.8"],
        "clean": [],
    }
    for name, extra in records.items():
        cli("simulate", "--robot", "hydrolek", "--input", tmp / "in.csv", "--out", tmp / f"{name}.csv",
            "--set", "joints.j2.valve.rated_flow=4.3e-5", "--noise-angle", 3e-4, "--seed", 1, *extra)
    spec = load_robot("hydrolek")
    rec = load_record(tmp / "clean.csv", spec)
    runner = Runner(rec)
    m0 = model_spec(spec)
    runner.simulate(m0)                      # compiled code loaded
    t0 = time.perf_counter()
    for _ in range(3):
        runner.simulate(m0)
    sim_s = (time.perf_counter() - t0) / 3

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    results = {"cpus": os.cpu_count(), "load_average_1min": load, "reference_simulation_s": sim_s, "runs": {}}
    worker_sets = [args.workers] + ([1] if args.sequential else [])
    for name in records:
        rec = load_record(tmp / f"{name}.csv", spec)
        for w in worker_sets:
            t0 = time.perf_counter()
            if not args.no_preload:
                report.preload()                # as the CLI does before an HTML report
            d = diagnosis.run(spec, rec, workers=w, progress=False)
            report.write(d, tmp / f"report_{name}_{w}", spec)       # the plots are part of the command
            el = time.perf_counter() - t0
            sims = sum(e.sims for r in d.evaluations for e in r)
            key = f"{name}/workers={w or os.cpu_count()}"
            results["runs"][key] = {
                "seconds": el, "target_s": TARGET_S, "ratio_to_target": el / TARGET_S, "goal_s": GOAL_S,
                "ratio_to_one_simulation": el / sim_s, "candidate_fits": sum(len(r) for r in d.evaluations),
                "candidate_simulations": sims, "verdict": d.verdict,
                "selected": [s["effect"] + "@" + str(s["joint"]) for s in d.selected], "stages_s": d.timings,
            }
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"{results['cpus']} CPUs, load average {load:.2f}; one 60 s simulation at default settings: {sim_s:.3f} s")
    print(f"{'record':<22} {'seconds':>8} {'target':>7} {'ratio':>6} {'goal':>5} {'x sim':>6} {'fits':>5} {'sims':>6}  verdict")
    for key, r in results["runs"].items():
        print(f"{key:<22} {r['seconds']:8.1f} {TARGET_S:7.0f} {r['ratio_to_target']:6.2f} {GOAL_S:5.0f} {r['ratio_to_one_simulation']:6.0f} "
              f"{r['candidate_fits']:5d} {r['candidate_simulations']:6d}  {r['verdict']} {' '.join(r['selected'])}")


if __name__ == "__main__":
    main()
