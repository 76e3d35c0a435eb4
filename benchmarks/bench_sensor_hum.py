"""Interference on the position sensor: mains hum picked up by a potentiometer's wiring, sampled by a
50 Hz logger. Aliased, 50 Hz hum is a slow wave, and with the logger's wandering clock a broadband one
(a random walk at the log's rate); 60 Hz hum is a line at 10 Hz. No model of the rig reproduces
either (``sim_core/identification/sensor_disturbance.py``, ``mains_tone.py``).

Each case: ``rig new TEMPLATE`` (boom by default) -> the tests' closed-loop generator
(``tests/rig_records.py``, the rig's valve flow x1.1 and supply x0.9 against its spec, start off,
jittered timestamps) -> ``a sin(2 pi f t)`` volts added to the logged sensor volts -> ``hydrohil
diagnose`` with the import options. The
reference in the same run is the clean log (a = 0), which must read ``no_significant_discrepancy``.
With ``--fed-back`` the hum is on the sensor the controller reads too (a controller that logs each of
its cycles): the command carries the hum's alias and the joint moves with it, in the record and in
the model alike. Printed per case: the verdict, what was named (and whether
marked ambiguous), which of the sensor's causes the report says first (``sensor``: a white
disturbance; ``mains``: a steady line where mains aliases, with its frequency), the baseline's angle
fit against its noise ceiling, and how far the final model's velocity sits under its ceiling. A hum
should read ``unexplained_discrepancy``, never a named effect; where the velocity sits more than 10
points under its ceiling with a white residual, the sensor is the cause said first; a 60 Hz hum that
leaves the record unexplained is said as mains.

    .venv/bin/python benchmarks/bench_sensor_hum.py [--seeds 3,4,5] [--amplitudes 0,0.005,0.01,0.02]
        [--hum-hz 49.93] [--template boom|cylinder|rotary] [--steady-clock | --fed-back]

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
from sim_core.identification.decision import misfit_in_noise  # noqa: E402

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
    ap.add_argument("--fed-back", action="store_true",
                    help="the hum on the sensor the controller reads too (the loop logs each of its cycles)")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench_hum_"))
    cli("rig", "new", args.template, "--out", work / "rig")
    joint = load_robot(work / "rig").joint_names[0]
    read = ["--no-header", "--column", "time=0", "--column", f"q_{joint}=1:sensor_volts", "--column", f"u_{joint}=2"]
    named_wrong = clean_wrong = cases = unexplained = said = mains = hummed = 0
    off = {f"joints.{joint}.valve.rated_flow": 1.1, "supply.pressure": 0.9}
    for seed in map(int, args.seeds.split(",")):
        if not args.fed_back:
            rows, _ = closed_loop_record(work / "rig", hidden=None, seed=seed, start_offset=0.03, rate=RATE_HZ, off=off)
        for amp in map(float, args.amplitudes.split(",")):
            if args.fed_back:
                log, _ = closed_loop_record(work / "rig", hidden=None, seed=seed, start_offset=0.03, rate=RATE_HZ,
                                            off=off, interference=lambda t: amp * np.sin(2 * np.pi * args.hum_hz * t + 0.3))
            else:
                log = rows.copy()
                at = np.arange(len(log)) / RATE_HZ if args.steady_clock else log[:, 0]
                log[:, 1] += amp * np.sin(2 * np.pi * args.hum_hz * at + 0.3)
            write_headerless(log, work / "log.csv")
            cli("diagnose", "--robot", work / "rig", work / "log.csv", *read, "--report", work / "rep", "--quiet")
            d = json.loads((work / "rep" / "diagnosis.json").read_text())
            named = ", ".join(s["effect"] + (" (ambiguous)" if s.get("ambiguous") else "") for s in d["selected"])
            fits, ceil = d["extended"]["channels"][joint], d["decision"]["channel_ceilings"][joint]
            u = d.get("unexplained") or {}
            causes = u.get("record_causes") or [""]
            line = u.get("mains_tone", {}).get(joint)
            first = "-"
            if joint in u.get("sensor_disturbance", {}) and causes[0].startswith(f"the position of {joint} carries a dist"):
                first = "sensor"
            elif line and causes[0].startswith(f"the position of {joint} carries a steady line"):
                first = f"mains {line['frequency_hz']:.1f} Hz"
            print(f"seed {seed} hum {1e3 * amp:5.1f} mV  {d['verdict']:27s} {named or '-':28s} first cause "
                  f"{first:15s} baseline angle "
                  f"{d['baseline']['fit'][joint]:6.2f} (ceiling {d['data']['fit_ceiling'][joint]:.2f}), velocity "
                  f"{ceil['velocity'] - fits['velocity']:5.1f} points under its ceiling "
                  f"({misfit_in_noise(fits['velocity'], ceil['velocity']):.2f} noises)", flush=True)
            cases += 1
            if amp == 0.0:
                clean_wrong += d["verdict"] != "no_significant_discrepancy"
            else:
                named_wrong += bool(d["selected"])
                unexplained += d["verdict"] == "unexplained_discrepancy"
                said += first == "sensor"
                mains += first.startswith("mains")
                hummed += 1
    print(f"\nwith hum ({hummed} cases): unexplained_discrepancy {unexplained}, a bank effect named {named_wrong} "
          f"(want 0), the sensor said first {said}, mains said first {mains}; clean reference: {clean_wrong} "
          f"false alarm(s) (want 0); {cases} cases")
    return 0


if __name__ == "__main__":
    sys.exit(main())
