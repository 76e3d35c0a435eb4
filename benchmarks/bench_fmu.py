"""Cost of one FMU communication step against Simulator.step, measured in the same run.

For each robot, on the same PRBS commands, called in turn at every step (all three follow the same
trajectory, whose cost varies with the state, and share the machine), microseconds per
communication step (median) of:
* Simulator.step (the reference);
* the FMU's Python slave called directly (set_real of the inputs, do_step, get_real of all
  outputs): the cost of the FMU's own Python layer;
* the exported FMU driven through FMPy's FMI 2.0 calls exactly as a co-simulation master does per
  step (fmi2SetReal, fmi2DoStep, fmi2GetReal): adds pythonfmu's binary and FMPy's ctypes calls;
and the ratio FMU / Simulator.step, at two communication steps. Also FMPy's simulate_fmu (its own
loop: input interpolation, recording) per step, for a user of that function.

    .venv/bin/python benchmarks/bench_fmu.py [--robot hydrolek --robot harvester] [--steps 4000] [--json]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np


def _prbs(spec, steps: int, dt: float):
    from sim_core.excitation import multilevel_prbs

    joint = spec.joint_names[min(1, len(spec.joint_names) - 1)]
    t, U = multilevel_prbs(spec, joint, levels=5, amplitude=5.0, duration=steps * dt, rate=1.0 / dt, seed=1)
    return t, U


def _direct(spec, dt: float):
    """Simulator.step on its own Context: a function of the command row."""
    from sim_core.plant import Plant
    from sim_core.simulator import Simulator

    sim = Simulator(Plant(spec).create_context(seed=0))
    return lambda u: sim.step(u, dt)


def _slave(fmu: Path, dt: float, folder: Path):
    """The FMU's Python slave called directly, as pythonfmu's binary calls it per step."""
    import zipfile

    from sim_core.export.fmu_slave import PlantSlave

    zipfile.ZipFile(fmu).extractall(folder)
    slave = PlantSlave(instance_name="bench", resources=str(folder / "resources"))
    vin = [i for i, v in enumerate(slave._vars) if v.causality == "input"]
    vout = [i for i, v in enumerate(slave._vars) if v.causality == "output"]
    slave.enter_initialization_mode()
    slave.exit_initialization_mode()
    clock = [0.0]

    def step(u):
        slave.set_real(vin, u)
        slave.do_step(clock[0], dt)
        slave.get_real(vout)
        clock[0] += dt

    return step


def _fmi(fmu: Path, dt: float):
    """The FMU through FMPy's FMI 2.0 calls, as a co-simulation master drives it per step."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(fmu))
    vin = [v.valueReference for v in md.modelVariables if v.causality == "input"]
    vout = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    clock = [0.0]

    def step(u):
        slave.setReal(vin, u)
        slave.doStep(currentCommunicationPoint=clock[0], communicationStepSize=dt)
        slave.getReal(vout)
        clock[0] += dt

    return step


def _interleaved(steppers: dict, U) -> dict:
    """Per-step seconds of each stepper, called in turn on every command row: all follow the same
    trajectory (the cost of a step depends on the state) and share the machine's interference."""
    rows = [list(map(float, u)) for u in U]
    for f in steppers.values():   # first call: load the compiled kernel
        f(rows[0])
    times = {k: np.empty(len(rows) - 1) for k in steppers}
    clock = time.perf_counter
    for i, u in enumerate(rows[1:]):
        for k, f in steppers.items():
            t0 = clock()
            f(u)
            times[k][i] = clock() - t0
    return times


def _simulate_fmu(fmu: Path, spec, t, U, dt: float) -> float:
    from fmpy import simulate_fmu

    sig = np.zeros(len(t), dtype=[("time", float)] + [(f"u_{j}", float) for j in spec.joint_names])
    sig["time"] = t
    for a, j in enumerate(spec.joint_names):
        sig[f"u_{j}"] = U[:, a]
    t0 = time.perf_counter()
    simulate_fmu(str(fmu), start_time=0.0, stop_time=float(t[-1]), output_interval=dt, input=sig)
    return (time.perf_counter() - t0) / (len(t) - 1)


def bench(robot: str, steps: int, dts=(1e-3, 1e-2)) -> dict:
    from sim_core.export.fmu_build import build_fmu
    from sim_core.model.spec import load_robot

    spec = load_robot(robot)
    out: dict = {"robot": robot, "steps": steps, "by_step": []}
    with tempfile.TemporaryDirectory() as d:
        fmu = build_fmu(spec, Path(d) / f"{robot}.fmu")
        for n, dt in enumerate(dts):
            _, U = _prbs(spec, steps, dt)
            times = _interleaved({"simulator": _direct(spec, dt), "slave": _slave(fmu, dt, Path(d) / f"x{n}"),
                                  "fmi": _fmi(fmu, dt)}, U)
            med = {k: float(np.median(v)) for k, v in times.items()}
            mean = {k: float(np.mean(v)) for k, v in times.items()}
            out["by_step"].append({
                "communication_step_s": dt,
                "median_us": {k: v * 1e6 for k, v in med.items()},
                "mean_us": {k: v * 1e6 for k, v in mean.items()},
                "ratio_fmi_to_simulator": med["fmi"] / med["simulator"],
                "overhead_fmi_us": (med["fmi"] - med["simulator"]) * 1e6,
                "overhead_slave_us": (med["slave"] - med["simulator"]) * 1e6,
                "fmu_real_time_factor": dt / med["fmi"],
            })
        t, U = _prbs(spec, steps, dts[0])
        out["simulate_fmu_us_per_step"] = _simulate_fmu(fmu, spec, t, U, dts[0]) * 1e6
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", action="append", help="robot (repeatable; default hydrolek and harvester)")
    ap.add_argument("--steps", type=int, default=4000, help="communication steps per measurement (default 4000)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    results = [bench(r, args.steps) for r in (args.robot or ["hydrolek", "harvester"])]
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print("median us per communication step (interleaved on the same PRBS); overhead = FMU - Simulator.step")
    print(f"{'robot':<10} {'step':>5} {'Simulator.step':>14} {'slave (Python)':>14} {'FMU via FMI':>12} {'ratio':>6} "
          f"{'overhead':>9} {'FMU RTF':>8}  simulate_fmu (1 ms)")
    for r in results:
        for row in r["by_step"]:
            m = row["median_us"]
            print(f"{r['robot']:<10} {row['communication_step_s'] * 1e3:3.0f}ms {m['simulator']:11.1f} us "
                  f"{m['slave']:11.1f} us {m['fmi']:9.1f} us {row['ratio_fmi_to_simulator']:6.2f} "
                  f"{row['overhead_fmi_us']:6.1f} us {row['fmu_real_time_factor']:8.1f}  "
                  f"{r['simulate_fmu_us_per_step']:.1f} us/step")


if __name__ == "__main__":
    main()
