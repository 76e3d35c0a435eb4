"""How ``hydrohil diagnose`` does on records unlike its tests' (issue 5: "other excitation signals,
magnitudes, joints, noise levels and combinations"): multisine and smoothed-noise inputs, two joints
moving at once, 100 Hz and 1 kHz records, 12-bit quantised angles, records without pressures, a
short record that does not start at t = 0, a nominal model that is off (supply pressure and bulk
modulus) with nothing hidden, two effects on the harvester, the MARS-ND platform. Every record is
made with ``hydrohil excite``/``simulate`` (or numpy for the inputs ``excite`` does not make) and
handed to the ``hydrohil diagnose`` command as a CSV.

    .venv/bin/python benchmarks/bench_diagnose_cases.py [--only NAME ...] [--json]

Prints per case what was hidden, what was named, the parameter error, the gain and the seconds;
the reference in the same run is the share of cases named right. About 5 minutes on 2 cores.
"""

import argparse
import csv
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RATE = 200


def cli(*args) -> None:
    subprocess.run([sys.executable, "-m", "sim_core.cli", *map(str, args)], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL)


def write_input(path: Path, cols: dict, rate: float, t0: float = 0.0) -> None:
    n = len(next(iter(cols.values())))
    t = t0 + np.arange(n) / rate
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time"] + [f"u_{j}" for j in cols])
        for i in range(n):
            w.writerow([f"{t[i]:.6f}"] + [f"{cols[j][i]:.6f}" for j in cols])


def multisine(amp: float, seconds: float, rng, freqs=(0.15, 0.35, 0.7, 1.3)) -> np.ndarray:
    t = np.arange(int(seconds * RATE)) / RATE
    u = sum(np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in freqs)
    return amp * u / np.abs(u).max()


def smooth_noise(amp: float, seconds: float, rng, tau: float = 0.4) -> np.ndarray:
    """First-order filtered white noise, its 4 s moving mean removed (no net drift to an end stop)."""
    w = rng.standard_normal(int(seconds * RATE))
    a = np.exp(-1.0 / (tau * RATE))
    y = np.zeros_like(w)
    for i in range(1, len(w)):
        y[i] = a * y[i - 1] + (1 - a) * w[i]
    y -= np.convolve(y, np.ones(4 * RATE) / (4 * RATE), mode="same")
    return amp * y / np.abs(y).max()


def prbs(amp: float, seconds: float, rate: float, rng, period: float = 0.5, levels: int = 5) -> np.ndarray:
    vals = rng.choice(np.linspace(-amp, amp, levels), int(seconds / period))
    return np.repeat(vals, int(period * rate))[: int(seconds * rate)]


def rewrite(src: Path, dst: Path, drop_pressures: bool = False, quantum: float | None = None) -> None:
    rows = list(csv.reader(open(src)))
    hdr = rows[0]
    keep = [i for i, c in enumerate(hdr) if not (drop_pressures and c.startswith("p_"))]
    with open(dst, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([hdr[i] for i in keep])
        for r in rows[1:]:
            w.writerow([f"{round(float(r[i]) / quantum) * quantum:.7f}" if quantum and hdr[i].startswith("q_") else r[i]
                        for i in keep])


# name: robot, input maker ("excite:<joint>[:rate]" or a callable of rng), simulate args, angle noise,
#       post-processing, expected [(effect, joint, {param: truth})]
def cases():
    return {
        "multisine_deadband_j3": ("hydrolek", lambda rng: ({"j3": multisine(4.0, 60, rng)}, RATE),
                                  ["--effect", "deadband:joint=j3,width=0.7"], 3e-4, {}, [("deadband", "j3", {"width": 0.7})]),
        "smooth_noise_asymmetry_j1": ("hydrolek", lambda rng: ({"j1": smooth_noise(5.0, 60, rng)}, RATE),
                                      ["--effect", "valve_asymmetry:joint=j1,ratio=0.8"], 3e-4, {},
                                      [("valve_asymmetry", "j1", {"ratio": 0.8})]),
        "two_joints_hysteresis_j3": ("hydrolek", lambda rng: ({"j2": prbs(4, 60, RATE, rng), "j3": prbs(4, 60, RATE, rng)}, RATE),
                                     ["--effect", "hysteresis:joint=j3,width=0.6"], 3e-4, {},
                                     [("hysteresis", "j3", {"width": 0.6})]),
        "noise_1mrad_delay_j2": ("hydrolek", "excite:j2", ["--effect", "delay:joint=j2,delay=0.05"], 1e-3, {},
                                 [("delay", "j2", {"delay": 0.05})]),
        "100Hz_spool_lag_j2": ("hydrolek", lambda rng: ({"j2": prbs(5, 60, 100, rng)}, 100),
                               ["--effect", "spool_lag:joint=j2,time_constant=0.07"], 3e-4, {},
                               [("spool_lag", "j2", {"time_constant": 0.07})]),
        "1kHz_12bit_backlash_j4": ("hydrolek", "excite:j4:1000", ["--effect", "backlash:joint=j4,width=0.02"], 2e-4,
                                   {"quantum": 2 * np.pi / 4096}, [("backlash", "j4", {"width": 0.02})]),
        "20s_from_t12_deadband_j2": ("hydrolek", lambda rng: ({"j2": prbs(5, 20, RATE, rng)}, RATE, 12.5),
                                     ["--effect", "deadband:joint=j2,width=0.9"], 3e-4, {}, [("deadband", "j2", {"width": 0.9})]),
        "no_pressures_friction_j2": ("hydrolek", "excite:j2", ["--effect", "coulomb_friction:joint=j2,torque=70"], 3e-4,
                                     {"drop_pressures": True}, [("coulomb_friction", "j2", {"torque": 70.0})]),
        "no_pressures_leakage_j2": ("hydrolek", "excite:j2", ["--effect", "leakage:joint=j2,internal=3e-12"], 3e-4,
                                    {"drop_pressures": True}, [("leakage", "j2", {"internal": 3e-12})]),
        "spool_lag_j5": ("hydrolek", "excite:j5", ["--effect", "spool_lag:joint=j5,time_constant=0.06"], 2e-4, {},
                         [("spool_lag", "j5", {"time_constant": 0.06})]),
        "clean_multisine_j4": ("hydrolek", lambda rng: ({"j4": multisine(4.0, 60, rng)}, RATE), [], 3e-4, {}, []),
        "clean_12bit_j1": ("hydrolek", "excite:j1", [], 2e-4, {"quantum": 2 * np.pi / 4096}, []),
        "harvester_friction+deadband_boom": ("harvester", lambda rng: ({"boom": prbs(6, 60, RATE, rng)}, RATE),
                                             ["--effect", "coulomb_friction:joint=boom,torque=6000",
                                              "--effect", "deadband:joint=boom,width=1.7"], 5e-4, {},
                                             [("coulomb_friction", "boom", {"torque": 6000.0}), ("deadband", "boom", {"width": 1.7})]),
        "harvester_friction_stick": ("harvester", "excite:stick", ["--effect", "coulomb_friction:joint=stick,torque=3000"],
                                     5e-4, {}, [("coulomb_friction", "stick", {"torque": 3000.0})]),
        "harvester_clean_multisine_swing": ("harvester", lambda rng: ({"swing": multisine(6.0, 60, rng)}, RATE), [], 3e-4, {}, []),
        "mars_nd_deadband_left_j2": ("mars_nd", "excite:left_j2", ["--effect", "deadband:joint=left_j2,width=0.8"], 3e-4, {},
                                     [("deadband", "left_j2", {"width": 0.8})]),
        # the nominal model is off (supply 8 % low, oil 18 % softer) and nothing is hidden: a real
        # discrepancy the bank has no exact name for; the answer should at least be flagged ambiguous
        "nominal_off_j2": ("hydrolek", "excite:j2", ["--set", "supply.pressure=12.9e6", "--set", "fluid.bulk_modulus=1.15e9"],
                           3e-4, {}, None),
    }


def run_case(name, case, tmp: Path, seed: int) -> dict:
    robot, make, sim_args, noise, post, expected = case
    rng = np.random.default_rng(seed)
    inp = tmp / f"{name}_in.csv"
    if isinstance(make, str):
        _, joint, *rate = make.split(":")
        cli("excite", "--robot", robot, "--joint", joint, "--duration", 60, "--rate", rate[0] if rate else RATE,
            "--seed", seed, "--out", inp)
    else:
        cols, rate, *t0 = make(rng)
        write_input(inp, cols, rate, *t0)
    raw = tmp / f"{name}_raw.csv"
    cli("simulate", "--robot", robot, "--input", inp, "--out", raw, "--noise-angle", noise, "--seed", seed, *sim_args)
    meas = tmp / f"{name}.csv"
    rewrite(raw, meas, **post)
    t0 = time.perf_counter()
    cli("diagnose", "--robot", robot, meas, "--report", tmp / f"rep_{name}", "--quiet")
    seconds = time.perf_counter() - t0
    d = json.loads((tmp / f"rep_{name}" / "diagnosis.json").read_text())
    named = [(s["effect"], s["joint"]) for s in d["selected"]]
    out = {"case": name, "seconds": round(seconds, 1), "verdict": d["verdict"], "named": named,
           "gains": [s["gain"] for s in d["selected"]], "ambiguous": [bool(s.get("ambiguous")) for s in d["selected"]]}
    if expected is None:
        out["right"] = None
        return out
    out["right"] = sorted(named, key=str) == sorted([(e, j) for e, j, _ in expected], key=str)
    errs = []
    if out["right"]:
        for e, j, truth in expected:
            s = next(s for s in d["selected"] if (s["effect"], s["joint"]) == (e, j))
            errs += [abs(s["params"][p] / v - 1.0) for p, v in truth.items()]
    out["max_param_error_pct"] = round(100 * max(errs), 2) if errs else None
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*", help="case names")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    all_cases = cases()
    names = args.only or list(all_cases)
    tmp = Path(tempfile.mkdtemp(prefix="bench_diagnose_cases_"))
    rows = [run_case(n, all_cases[n], tmp, seed=11 + i) for i, n in enumerate(names)]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print(f"{'case':34s} {'right':5s} {'named (gain, points)':58s} {'param err':>9s} {'s':>5s}")
    for r in rows:
        named = ", ".join(f"{e}@{j} ({g:.1f}{', ambiguous' if a else ''})"
                          for (e, j), g, a in zip(r["named"], r["gains"], r["ambiguous"])) or r["verdict"]
        right = {True: "yes", False: "NO", None: "-"}[r["right"]]
        err = f"{r['max_param_error_pct']:.1f} %" if r.get("max_param_error_pct") is not None else ""
        print(f"{r['case']:34s} {right:5s} {named:58s} {err:>9s} {r['seconds']:5.0f}")
    judged = [r for r in rows if r["right"] is not None]
    print(f"named right: {sum(r['right'] for r in judged)} / {len(judged)}; records in {tmp}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
