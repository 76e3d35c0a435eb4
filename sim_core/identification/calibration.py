"""Calibration of nominal parameters by output error (``hydrohil fit`` and diagnose's baseline).

By default the free parameters are the valve flow gains (``joints.<j>.valve.rated_flow``) of the
commanded, measured joints: the number every valve-controlled joint's speed scales with and the one
a datasheet gets least right. Supply pressure, link masses and sensor calibrations are not freed by
default: without pressure sensors they would absorb a payload, friction or a sensor offset, which
``diagnose`` must be able to name (free them with ``--free`` when that is what you want).
"""

from __future__ import annotations

from dataclasses import dataclass

from . import output_error as oe
from .parameters import FreeParameter, free_parameter
from .record import Record
from .simulation import Runner


def default_free(spec, rec: Record) -> list[str]:
    return [f"joints.{j}.valve.rated_flow" for j in rec.targets]


@dataclass
class Calibration:
    spec: object                     # the calibrated model spec
    result: oe.FitResult
    free: list[FreeParameter]


# factors around the nominal flow gain tried before least squares
SCAN_FACTORS = (0.5, 0.63, 0.8, 0.9, 1.1, 1.25, 1.6, 2.0)


def calibrate(spec, runner: Runner, problem: oe.Problem, keys: list[str], *, span: float = 10.0,
              max_sims: int = 40, uncertainty: bool = True) -> Calibration:
    """Fit ``keys`` of ``spec`` (a model spec) on the problem's channels, flow gains from the best
    point of a coarse scan."""
    free = [free_parameter(spec, k, span=span) for k in keys]
    start = scan_flow_gains(spec, runner, problem, keys)
    res = oe.fit(runner, problem, start, free, max_sims=max_sims, uncertainty=uncertainty)
    return Calibration(res.spec, res, free)


def scan_flow_gains(spec, runner: Runner, problem: oe.Problem, keys: list[str]):
    """``spec`` with each flow gain among ``keys`` moved to the best of ``SCAN_FACTORS`` x its value
    (one joint after the other). Along a flow gain the output-error cost is jagged wherever
    stick-slip, a deadband crossing or end-stop contact switches on or off; a finite-difference
    gradient there is noise and least squares from the nominal value can stall far from the valley
    (seen: a cost 6x the scan's best after 40 simulations)."""
    def cost(s) -> float:
        r = problem.residuals(runner.simulate(s, problem.n))
        return float(r @ r)

    best_spec = spec.copy()
    best = cost(best_spec)
    for key in keys:
        if not key.endswith(".valve.rated_flow"):
            continue
        v0 = best_spec.get(key)
        best_v = v0
        for f in SCAN_FACTORS:
            trial = best_spec.copy()
            trial.set(key, v0 * f)
            c = cost(trial)
            if c < best:
                best, best_v = c, v0 * f
        best_spec.set(key, best_v)
    return best_spec
