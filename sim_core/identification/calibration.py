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


def calibrate(spec, runner: Runner, problem: oe.Problem, keys: list[str], *, span: float = 10.0,
              max_sims: int = 40, uncertainty: bool = True) -> Calibration:
    """Fit ``keys`` of ``spec`` (a model spec) on the problem's channels."""
    free = [free_parameter(spec, k, span=span) for k in keys]
    res = oe.fit(runner, problem, spec, free, max_sims=max_sims, uncertainty=uncertainty)
    return Calibration(res.spec, res, free)
