"""One reproduction run of a scenario: emulator subprocess + controller process over CAN, the
in-process comparison runs, metrics and figures."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from hil_server.launcher import ServerProcess

from .plant_local import LocalPlant, configured_spec
from .scenarios import ANALYSE, SCENARIOS, make_controller
from .tracking import run_loop


def write_params(scenario, out: Path) -> Path | None:
    if not scenario.params:
        return None
    from sim_core.params_file import write_params as write_params_file

    path = out / f"{scenario.name}_params.toml"
    write_params_file(path, scenario.params)
    return path


def load_trace(path: Path) -> dict:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def run_emulated(scenario, out: Path, mode: str, duration: float, params: Path | None, variant: str = "",
                 timeout_s: float = 1800.0) -> tuple[dict, dict]:
    """Start ``hydrohil serve`` for the scenario, reset it, run the controller as a separate process
    over CAN; returns (trace, the controller's JSON summary)."""
    feedback = scenario.control_rate_hz if mode == "realtime" else 100.0
    (out / "traces").mkdir(parents=True, exist_ok=True)
    trace_path = out / "traces" / f"{scenario.name}_{variant or 'emulated'}_{mode}.npz"
    args = ["--mode", mode, "--rate", f"{scenario.plant_rate_hz:g}", "--feedback-rate", f"{feedback:g}",
            "--log-level", "warning"] + (["--params", str(params)] if params else [])
    with ServerProcess(*args, robot=scenario.robot, can="socketcand", workdir=out / "serve") as emu:
        emu.rest.reset(scenario.seed)
        cmd = [sys.executable, "-m", "controllers.client", "--scenario", scenario.name, "--robot", scenario.robot,
               "--port", str(emu.can_port), "--mode", mode, "--duration", f"{duration:g}",
               "--tick", f"{1.0 / scenario.plant_rate_hz:.17g}", "--ticks", str(scenario.ticks),
               "--feedback-rate", f"{feedback:g}", "--out", str(trace_path)]
        if variant:
            cmd += ["--variant", variant]
        if params:
            cmd += ["--params", str(params)]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s,
                              cwd=str(Path(__file__).resolve().parent.parent))
        if proc.returncode != 0:
            raise RuntimeError(f"controller process failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
        summary = json.loads(proc.stdout.strip().splitlines()[-1])
        loop = emu.rest.state().get("loop", {})
        summary["emulator_loop"] = {k: loop.get(k) for k in ("ticks", "overruns", "resyncs", "watchdog_trips",
                                                              "lateness_us", "realtime_priority")}
    trace = load_trace(trace_path)
    # the controller's period as it saw it (realtime: feedback arrival; lockstep: exact)
    dt = np.diff(trace["t"])
    summary["period_s"] = {"median": float(np.median(dt)), "max": float(np.max(dt))} if len(dt) else {}
    return trace, summary


def run_local(scenario, variant: str, duration: float, params: Path | None) -> dict:
    """The same controller in-process (no CAN); ``simulated_quantized`` passes every signal through the DBC."""
    spec = configured_spec(scenario.robot, params)
    plant = LocalPlant(scenario.robot, spec=spec, seed=scenario.seed, tick_s=1.0 / scenario.plant_rate_hz,
                       ticks=scenario.ticks, quantize=(variant == "simulated_quantized"))
    return run_loop(plant, make_controller(scenario.name, spec, variant), duration)


def run_scenario(name: str, out: str | Path, mode: str = "lockstep", duration: float | None = None,
                 plots: bool = True) -> dict:
    """Run scenario ``name``: emulated (CAN) + its local comparison runs; metrics (also written to
    ``<out>/<name>.json``) with the figure paths under ``figures``. The controller's trace goes to
    ``<out>/traces/``, the emulator's log to ``<out>/serve/``."""
    if name not in SCENARIOS:
        raise KeyError(f"unknown scenario {name!r}; scenarios: {', '.join(SCENARIOS)}, all")
    if mode not in ("lockstep", "realtime"):
        raise ValueError(f"--mode {mode!r}: lockstep or realtime")
    sc = SCENARIOS[name]
    duration = sc.duration if duration is None else float(duration)
    if not duration > 0.0:
        raise ValueError(f"--duration {duration}: must be > 0 s")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    params = write_params(sc, out)
    t0 = time.perf_counter()
    runs: dict[str, dict] = {}
    runs["emulated"], summary = run_emulated(sc, out, mode, duration, params)
    t_emulated = time.perf_counter() - t0
    for variant in sc.local_runs:
        runs[variant] = run_local(sc, variant, duration, params)
    spec = configured_spec(sc.robot, params)
    metrics = ANALYSE[name](spec, runs)
    metrics["run"] = {"scenario": name, "title": sc.title, "robot": sc.robot, "mode": mode, "duration_s": duration,
                      "plant_rate_hz": sc.plant_rate_hz, "control_rate_hz": sc.control_rate_hz, "seed": sc.seed,
                      "controller": summary, "emulated_wall_s": t_emulated,
                      "params_file": str(params) if params else None}
    if plots:
        from .plots import PLOTS

        metrics["figures"] = [str(p) for p in PLOTS[name](spec, runs, metrics, out)]
    (out / f"{name}.json").write_text(json.dumps(metrics, indent=2, default=float))
    return metrics
