"""Interference on the position sensor: mains hum picked up by a potentiometer's wiring, sampled by a
50 Hz logger. Aliased, it is a slow wave, and with the logger's wandering clock a broadband one (a
random walk at the log's rate); no model of the rig reproduces either
(``sim_core/identification/sensor_disturbance.py``).

Each case: ``rig new TEMPLATE`` (boom by default) -> the tests' closed-loop generator
(``tests/rig_records.py``, the rig's valve flow x1.1 and supply x0.9 against its spec, start off,
jittered timestamps) -> ``a sin(2 pi f t)`` volts added to the logged sensor volts -> ``hydrohil
diagnose`` with the import options. The
reference in the same run is the clean log (a = 0), which must read ``no_significant_discrepancy``.
Printed per case: the verdict, what was named (and whether marked ambiguous), whether the report's
first record cause is the disturbance on the sensor, the baseline's angle fit against its noise
ceiling, and how far the final model's velocity sits under its ceiling. A hum should read
``unexplained_discrepancy``, never a named effect; where the velocity sits more than 10 points under
its ceiling with a white residual, the sensor is the cause said first.

    .venv/bin/python benchmarks/bench_sensor_hum.py [--seeds 3,4,5] [--amplitudes 0,0.005,0.01,0.02]
        [--hum-hz 49.93] [--template boom|cylinder|rotary] [--steady-clock]

About 30 s per case on this 2-core VM.
"""

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from rig_records import closed_loop_record, write_headerless  # noqa: E402

from sim_core.model.spec import load_robot  # noqa: E402

RATE_HZ = 50.0   # the logger's rate (closed_loop_record's)


def cli(*args) -> None:
    p = subprocess.run([sys.executable, "-m", "sim_core.cli", *map(str, args)], capture_output=True, text=True, cwd=ROOT)
    if p.returncode:
        raise RuntimeError(p.stderr.strip()[-400:])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="3,4,5")
    ap.add_argument("--amplitudes", default="0,0.005,0.01,0.02", help="hum amplitudes, V at the sensor")
    ap.add_argument("--hum-hz", type=float, default=49.93)
    ap.add_argument("--template", default="boom", help="the rig: a `hydrohil rig new` template")
    ap.add_argument("--steady-clock", action="store_true",
                    help="sample the hum at the nominal instants k / RATE_HZ (a logger whose clock does not wander: "
                         "a clean slow alias), not at the logged, jittered times")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench_hum_"))
    cli("rig", "new", args.template, "--out", work / "rig")
    joint = load_robot(work / "rig").joint_names[0]
    read = ["--no-header", "--column", "time=0", "--column", f"q_{joint}=1:sensor_volts", "--column", f"u_{joint}=2"]
    named_wrong = clean_wrong = cases = unexplained = said = hummed = 0
    for seed in map(int, args.seeds.split(",")):
        rows, _ = closed_loop_record(work / "rig", hidden=None, seed=seed, start_offset=0.03, rate=RATE_HZ,
                                     off={f"joints.{joint}.valve.rated_flow": 1.1, "supply.pressure": 0.9})
        for amp in map(float, args.amplitudes.split(",")):
            log = rows.copy()
            at = np.arange(len(log)) / RATE_HZ if args.steady_clock else log[:, 0]
            log[:, 1] += amp * np.sin(2 * np.pi * args.hum_hz * at + 0.3)
            write_headerless(log, work / "log.csv")
            cli("diagnose", "--robot", work / "rig", work / "log.csv", *read, "--report", work / "rep", "--quiet")
            d = json.loads((work / "rep" / "diagnosis.json").read_text())
            named = ", ".join(s["effect"] + (" (ambiguous)" if s.get("ambiguous") else "") for s in d["selected"])
            fits, ceil = d["extended"]["channels"][joint], d["decision"]["channel_ceilings"][joint]
            causes = (d.get("unexplained") or {}).get("record_causes") or [""]
            sensor = joint in (d.get("unexplained") or {}).get("sensor_disturbance", {})
            first = "sensor" if sensor and causes[0].startswith(f"the position of {joint}") else "-"
            print(f"seed {seed} hum {1e3 * amp:5.1f} mV  {d['verdict']:27s} {named or '-':28s} first cause "
                  f"{first:6s} baseline angle "
                  f"{d['baseline']['fit'][joint]:6.2f} (ceiling {d['data']['fit_ceiling'][joint]:.2f}), velocity "
                  f"{ceil['velocity'] - fits['velocity']:5.1f} points under its ceiling", flush=True)
            cases += 1
            if amp == 0.0:
                clean_wrong += d["verdict"] != "no_significant_discrepancy"
            else:
                named_wrong += bool(d["selected"])
                unexplained += d["verdict"] == "unexplained_discrepancy"
                said += first == "sensor"
                hummed += 1
    print(f"\nwith hum ({hummed} cases): unexplained_discrepancy {unexplained}, a bank effect named {named_wrong} "
          f"(want 0), the sensor said first {said}; clean reference: {clean_wrong} false alarm(s) (want 0); "
          f"{cases} cases")
    return 0


if __name__ == "__main__":
    sys.exit(main())
