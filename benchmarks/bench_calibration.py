"""The baseline calibration with its independent simulations side by side against the same
calibration run in one process, on the records a user's rig gives and on HydroLek's.

The calibration is the serial stage of ``hydrohil diagnose`` (and most of ``hydrohil fit``): before any
candidate is fitted, and again after each named effect (the recalibration), one least-squares fit runs
while the other core idles. A rig frees half a dozen parameters (supply, flow gain, load, sensor gain
and offset, viscous friction), each a Jacobian column; the flow-gain scan before it is nine
independent simulations. Run side by side (``calibration.calibrate(..., side=SideBySide(workers))``)
they are the same simulations, so the calibration is the same: checked here on every repetition.

Records: ``rig new cylinder`` and ``rig new boom`` under closed-loop P control (the tests' generator,
``tests/rig_records.py``: 60 s at 50 Hz, jittered time, nominal parameters off, a hidden 4 % leak), and
60 s of HydroLek's shoulder at 200 Hz with a hidden deadband (one flow gain free: only the scan runs side
by side there). The two ways alternate, ``--repeats`` times each; the medians and their ratio are printed.
Then the same for ``hydrohil fit``'s whole run (``run_fit``, ``--workers 1`` against the default), whose
polish and refits simulate at the default integrator step (ten times longer simulations).

    .venv/bin/python benchmarks/bench_calibration.py [--repeats 5] [--fit-repeats 3] [--workers 0] [--json]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))     # the record generator the tests use

from bench_rig_diagnosis import hidden_params  # noqa: E402   (the leak the rig benchmark hides: 4 % of full flow)
from rig_records import closed_loop_record, write_headerless  # noqa: E402

from sim_core.identification import output_error as oe  # noqa: E402
from sim_core.identification.calibration import calibrate, plan  # noqa: E402
from sim_core.identification.fitting import run_fit  # noqa: E402
from sim_core.identification.record import ESTIMATION_SHARE, load_record  # noqa: E402
from sim_core.identification.side_by_side import SideBySide  # noqa: E402
from sim_core.identification.simulation import choose_numerics, model_spec  # noqa: E402
from sim_core.model.spec import load_robot  # noqa: E402


def cli(*args):
    subprocess.run([sys.executable, "-m", "sim_core.cli", *map(str, args)], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL)


def rig_record(tmp: Path, template: str):
    """A closed-loop log of ``rig new TEMPLATE`` (flow x1.2, supply x0.85, a 4 % leak), imported."""
    work = tmp / template
    cli("rig", "new", template, "--out", work / "rig")
    spec = load_robot(work / "rig")
    joint = spec.joint_names[0]
    i = spec.tree.index(spec.joint(joint).dof)
    rows, _ = closed_loop_record(work / "rig", hidden=("leakage", hidden_params("leakage", spec, joint)),
                                 off={f"joints.{joint}.valve.rated_flow": 1.2, "supply.pressure": 0.85}, seed=1,
                                 start_offset=0.05 * float(spec.tree.upper[i] - spec.tree.lower[i]))
    write_headerless(rows, work / "log.csv")
    cli("import", work / "log.csv", "--robot", work / "rig", "--out", work / "rec.csv", "--no-header",
        "--column", "time=0", "--column", f"q_{joint}=1:sensor_volts", "--column", f"u_{joint}=2")
    return spec, load_record(work / "rec.csv", spec)


def hydrolek_record(tmp: Path):
    cli("excite", "--robot", "hydrolek", "--joint", "j2", "--duration", 60, "--rate", 200, "--seed", 7,
        "--out", tmp / "in.csv")
    cli("simulate", "--robot", "hydrolek", "--input", tmp / "in.csv", "--out", tmp / "hl.csv", "--noise-angle", 3e-4,
        "--seed", 1, "--set", "joints.j2.valve.rated_flow=4.3e-5", "--effect", "deadband:joint=j2,width=0.8")
    spec = load_robot("hydrolek")
    return spec, load_record(tmp / "hl.csv", spec)


def measure(spec, rec, repeats: int, workers: int, fit_repeats: int) -> dict:
    m0 = model_spec(spec)
    pl = plan(m0, rec)
    est = oe.Problem(rec, rec.targets, n=int(rec.n * ESTIMATION_SHARE))
    fast, _ = choose_numerics(m0, rec, est.n)
    fast.simulate(m0, est.n)                    # compiled code loaded
    times = {"one process": [], "side by side": []}
    ref = None
    for _ in range(repeats):
        for way in times:
            t0 = time.perf_counter()
            if way == "one process":
                cal = calibrate(m0, fast, est, free=pl.free, why=pl.why)
            else:
                with SideBySide(workers) as side:
                    cal = calibrate(m0, fast, est, free=pl.free, why=pl.why, side=side)
            times[way].append(time.perf_counter() - t0)
            if ref is None:
                ref = cal.changes
            elif cal.changes != ref:
                raise SystemExit(f"{spec.name}: the calibration {way} differs from the first one")
    serial, side = statistics.median(times["one process"]), statistics.median(times["side by side"])
    fits = {"one process": [], "side by side": []}
    ref_fit = None
    for _ in range(fit_repeats):
        for way in fits:
            t0 = time.perf_counter()
            res = run_fit(spec, rec, None, workers=1 if way == "one process" else workers)
            fits[way].append(time.perf_counter() - t0)
            ref_fit = ref_fit or res["parameters"]
            if res["parameters"] != ref_fit:
                raise SystemExit(f"{spec.name}: hydrohil fit {way} differs from the first one")
    fit_serial = statistics.median(fits["one process"]) if fit_repeats else float("nan")
    fit_side = statistics.median(fits["side by side"]) if fit_repeats else float("nan")
    return {"free": len(pl.free), "one_process_s": serial, "side_by_side_s": side, "ratio": side / serial,
            "identified": [c["parameter"] for c in ref if c["identified"]], "same_calibration": True,
            "fit_one_process_s": fit_serial, "fit_side_by_side_s": fit_side, "fit_ratio": fit_side / fit_serial,
            "all_s": times, "fit_all_s": fits}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--workers", type=int, default=0, help="side-by-side processes (0: CPU count)")
    ap.add_argument("--fit-repeats", type=int, default=3, help="runs of hydrohil fit's whole calibration each way")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_calibration_"))
    cases = {"rig new cylinder (50 Hz, closed loop)": lambda: rig_record(tmp, "cylinder"),
             "rig new boom (50 Hz, closed loop)": lambda: rig_record(tmp, "boom"),
             "hydrolek j2 (200 Hz)": lambda: hydrolek_record(tmp)}
    load = os.getloadavg()[0]
    results = {"cpus": os.cpu_count(), "load_average_1min": load, "cases": {}}
    for name, make in cases.items():
        spec, rec = make()
        results["cases"][name] = measure(spec, rec, args.repeats, args.workers, args.fit_repeats)
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"{results['cpus']} CPUs, load average {load:.2f}; medians of {args.repeats} alternating runs")
    print(f"{'record':<40} {'free':>4} {'calibrate: one process':>23} {'side by side':>13} {'ratio':>6}"
          f" {'fit: one process':>17} {'side by side':>13} {'ratio':>6}  identified")
    for name, r in results["cases"].items():
        print(f"{name:<40} {r['free']:4d} {r['one_process_s']:22.2f}s {r['side_by_side_s']:12.2f}s {r['ratio']:6.2f}"
              f" {r['fit_one_process_s']:16.2f}s {r['fit_side_by_side_s']:12.2f}s {r['fit_ratio']:6.2f}  "
              f"{', '.join(r['identified'])}")


if __name__ == "__main__":
    main()
