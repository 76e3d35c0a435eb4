"""Is a record closed loop? ``closed_loop.joint_evidence`` over records whose answer is known, the
increments' test alone printed beside it as the reference measured in the same run.

Closed loop: every ``rig new`` template's P or PI loop (integral time 1 or 0.3 s; ``tests/rig_records.py``,
the rig 20 % off its flow and 15 % off its supply) tracking set-point steps or a slow sine, the controller at the log's
50 Hz or at 1 kHz with every 20th sample logged; printed per record: the increments' correlation and
gain, the evidence's (which test gave it), and the controller's proportional gain; summed: how many
were found, and how many with the proportional gain within 5 %.
Open loop: the scored matrix's HydroLek records (``bench_diagnose_matrix.py``: PRBS, multisine,
operator doublets; singles, pairs, clean and out-of-bank), none of which may be found closed; printed:
how many were, and the most negative correlation of each test.

    .venv/bin/python benchmarks/bench_closed_loop_detection.py [--templates cylinder,boom,rotary]
        [--seeds 2] [--open-loop-seeds 3] [--no-open-loop]

About 1 minute for the closed loops and 5 for the open-loop records on this 2-core VM.
"""

import argparse
import subprocess
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from rig_records import closed_loop_record, reference_steps, sine_reference  # noqa: E402

from sim_core.identification import closed_loop as cl  # noqa: E402
from sim_core.model.spec import load_robot  # noqa: E402

REFERENCES = {"steps": reference_steps, "sine": sine_reference}
INTEGRAL_TIMES = (None, 1.0, 0.3)   # P, and PI with these integral times (s)
GAIN_TOLERANCE = 0.05   # a gain this close to the controller's proportional gain counts as given


def closed_loops(templates: list[str], seeds: int, work: Path) -> tuple[int, int, int, int, int]:
    """Print each closed-loop record's evidence; (records, found by the increments, found by the
    evidence, the increments' gain within ``GAIN_TOLERANCE`` of the controller's proportional gain,
    the evidence's)."""
    n = by_increments = found = first_gain = gain = 0
    for template in templates:
        rig = work / template
        subprocess.run([sys.executable, "-m", "sim_core.cli", "rig", "new", template, "--out", str(rig)], check=True,
                       cwd=ROOT, capture_output=True)
        spec = load_robot(rig)
        j = spec.joint_names[0]
        i = spec.tree.index(spec.joint(j).dof)
        span = float(spec.tree.upper[i] - spec.tree.lower[i])
        a, b = float(spec.get(f"joints.{j}.sensor.A")), float(spec.get(f"joints.{j}.sensor.B"))
        kp = spec.joint(j).command_range[1] / (0.2 * span)      # full command for 20 % of the range
        off = {f"joints.{j}.valve.rated_flow": 1.2, "supply.pressure": 0.85}
        for reference in REFERENCES:
            for ti in INTEGRAL_TIMES:
                for log_every in (1, 20):
                    for seed in range(1, seeds + 1):
                        rows, _ = closed_loop_record(rig, hidden=None, off=off, seed=seed, duration=60.0,
                                                     start_offset=0.05 * span, log_every=log_every, ti=ti, kp=kp,
                                                     reference=REFERENCES[reference])
                        t, y, u = rows[:, 0], a * rows[:, 1] + b, rows[:, 2]
                        first = cl.increments_evidence(u, y, spec.joint(j).command_range)
                        ev = cl.joint_evidence(u, y, spec.joint(j).command_range, t)
                        n += 1
                        by_increments += first["closed_loop"]
                        found += ev["closed_loop"]
                        first_gain += first["closed_loop"] and abs(first["gain"] / kp - 1) <= GAIN_TOLERANCE
                        gain += ev["closed_loop"] and abs(ev["gain"] / kp - 1) <= GAIN_TOLERANCE
                        print(f"{template:8s} {reference:5s} {f'PI {ti:g} s' if ti else 'P':8s} controller {50 * log_every:5d} Hz "
                              f"seed {seed}: increments {first['correlation']:+.2f} (K {first['gain']:.3g}); "
                              f"evidence {ev['correlation']:+.2f} (K {ev['gain']:.3g}, {ev['test']}, "
                              f"{'closed' if ev['closed_loop'] else 'OPEN'}); kp {kp:.3g}", flush=True)
    return n, by_increments, found, first_gain, gain


def _open_record(case: dict) -> list[tuple[str, float, float, bool]]:
    import bench_diagnose_matrix as m
    case = dict(case, group="detection")            # no trace simulations
    with tempfile.TemporaryDirectory(prefix="bench_cl_") as tmp:
        csv, robot, _ = m.builtin_record(Path(tmp), case)
        d = np.genfromtxt(csv, delimiter=",", names=True)
    spec = load_robot(robot)
    out = []
    for j in spec.joint_names:
        if f"u_{j}" not in d.dtype.names or f"q_{j}" not in d.dtype.names or np.ptp(d[f"u_{j}"]) == 0:
            continue
        u, y, t = d[f"u_{j}"], d[f"q_{j}"], d["time"]
        command_range = spec.joint(j).command_range
        out.append((case["id"], cl.increments_evidence(u, y, command_range)["correlation"],
                    cl.local_residual_evidence(u, y, command_range, t)["correlation"],
                    cl.joint_evidence(u, y, command_range, t)["closed_loop"]))
    return out


def open_loops(seeds: int) -> tuple[int, int, float, float]:
    """The matrix's open-loop records: (joints tested, found closed, worst increments, worst local residuals)."""
    import bench_diagnose_matrix as m
    cases = m.build(seeds, set(m.GROUPS), {"hydrolek"})
    rows = []
    with ProcessPoolExecutor(2) as pool:
        for res in pool.map(_open_record, cases):
            rows += res
    for cid, c1, c2, closed in rows:
        if closed:
            print(f"  found closed: {cid} (increments {c1:+.2f}, local residuals {c2:+.2f})")
    return len(rows), sum(r[3] for r in rows), min(r[1] for r in rows), min(r[2] for r in rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--templates", default="cylinder,boom,rotary")
    ap.add_argument("--seeds", type=int, default=2, help="seeds per closed-loop case")
    ap.add_argument("--open-loop-seeds", type=int, default=3, help="the matrix's seeds for its open-loop records")
    ap.add_argument("--no-open-loop", action="store_true", help="skip the matrix's open-loop records")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_cl_") as tmp:
        n, first, found, first_gain, gain = closed_loops(args.templates.split(","), args.seeds, Path(tmp))
    print(f"\nclosed-loop records found closed: {found}/{n} (the increments alone: {first}/{n})")
    print(f"... found with the proportional gain within {GAIN_TOLERANCE:.0%}: {gain}/{n} (the increments alone: {first_gain}/{n})")
    if not args.no_open_loop:
        m, wrong, c1, c2 = open_loops(args.open_loop_seeds)
        print(f"open-loop records found closed: {wrong}/{m}; most negative correlation: increments {c1:+.2f}, "
              f"local residuals {c2:+.2f} (threshold {cl.CORRELATION_LIMIT:g})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
