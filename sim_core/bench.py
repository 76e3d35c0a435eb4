"""Speed of the fixed-step kernel, measured against a variable-step solver of the same model.

For each robot: a PRBS on every joint at a 1 kHz output rate.

* ``real_time_factor``/``us_per_output_step``: batch mode (one compiled call for the run; what
  ``simulate`` and the identification use), best of ``repeat`` runs.
* ``us_per_step_call``: one call per 1 ms tick from Python, the real-time loop's pattern.
* ``reference``: scipy LSODA on the same equations (``sim_core.reference``). Its tolerance is
  loosened in decades from 1e-8 until its error against a Radau rtol 1e-9 solution exceeds the
  fixed-step kernel's error; the loosest tolerance that still matches is timed, and
  ``ratio_to_reference`` = reference time / kernel time at equal accuracy.

Other packages add sections through the ``hydrohil.benchmarks`` entry-point group.
"""

from __future__ import annotations

import time
from importlib.metadata import entry_points

import numpy as np

from .excitation import multilevel_prbs
from .plant import Plant
from .reference import solve_reference
from .simulator import Simulator


def prbs_all_joints(spec, duration: float, rate: float = 1000.0, amplitude: float = 5.0, seed: int = 0):
    n = int(round(duration * rate)) + 1
    t = np.arange(n) / rate
    U = np.zeros((n, len(spec.joint_names)))
    for a, j in enumerate(spec.joint_names):
        _, Uj = multilevel_prbs(spec, j, levels=5, amplitude=amplitude, duration=duration, rate=rate,
                                seed=seed + a, period=0.4, guard=False)
        U[:, a] = Uj[:, a]
    return t, U


def _rms_mrad(q, qref, idx) -> float:
    return float(np.max(np.sqrt(np.mean((q[:, idx] - qref[:, idx]) ** 2, axis=0))) * 1e3)


def bench_robot(name: str, duration: float = 10.0, repeat: int = 3, reference: bool = True,
                reference_duration: float = 0.5) -> dict:
    plant = Plant.from_robot(name)
    t, U = prbs_all_joints(plant.spec, duration)
    Simulator(plant.create_context()).run(t[:3], U[:3])  # compile / load cache
    best = np.inf
    for _ in range(repeat):
        sim = Simulator(plant.create_context())
        t0 = time.perf_counter()
        sim.run(t, U)
        best = min(best, time.perf_counter() - t0)
    n_steps = len(t) - 1
    h = plant.spec.integrator["max_substep"]
    out = {
        "output_rate_hz": 1000.0,
        "substep_s": h,
        "substeps_per_output_step": int(np.ceil(1e-3 / h - 1e-9)),
        "simulated_s": duration,
        "wall_s": best,
        "real_time_factor": duration / best,
        "us_per_output_step": best / n_steps * 1e6,
    }
    # one Python call per tick, as the real-time loop does
    sim = Simulator(plant.create_context())
    m = min(n_steps, 2000)
    sim.step(U[0], 1e-3)
    t0 = time.perf_counter()
    for k in range(m):
        sim.step(U[k], 1e-3)
    out["us_per_step_call"] = (time.perf_counter() - t0) / m * 1e6
    if reference:
        out["reference"] = _reference(plant, t, U, reference_duration)
        out["ratio_to_reference"] = out["reference"]["us_per_output_step"] / out["us_per_output_step"]
    return out


def _reference(plant, t, U, horizon: float) -> dict:
    k = int(round(horizon * 1000.0)) + 1
    tt, UU = t[:k], U[:k]
    idx = [plant.tree.index(plant.spec.joint(j).dof) for j in plant.joint_names]
    truth, _ = solve_reference(plant.create_context(), tt, UU, method="Radau", rtol=1e-9)
    fixed = Simulator(plant.create_context()).run(tt, UU).q
    err_fixed = _rms_mrad(fixed, truth, idx)
    chosen = None
    for rtol in (1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2):
        t0 = time.perf_counter()
        q, _ = solve_reference(plant.create_context(), tt, UU, method="LSODA", rtol=rtol)
        el = time.perf_counter() - t0
        err = _rms_mrad(q, truth, idx)
        if err <= max(err_fixed, 1e-6) or chosen is None:
            chosen = {"solver": "scipy LSODA", "rtol": rtol, "rms_error_mrad": err, "wall_s": el,
                      "us_per_output_step": el / (k - 1) * 1e6}
        if err > err_fixed:
            break
    chosen["fixed_step_rms_error_mrad"] = err_fixed
    chosen["truth"] = "scipy Radau rtol 1e-9"
    chosen["horizon_s"] = horizon
    return chosen


def run_bench(robots=None, duration: float = 10.0, reference: bool = True, plugins: bool = True) -> dict:
    robots = robots or ["hydrolek", "mars_nd", "harvester"]
    result = {name: bench_robot(name, duration=duration, reference=reference) for name in robots}
    if plugins:
        for ep in entry_points(group="hydrohil.benchmarks"):
            result.update(ep.load()())
    return result
