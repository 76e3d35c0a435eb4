"""A disturbance on the measured position that no motion of the joint makes.

Mains hum picked up by a potentiometer's wiring and sampled by a 50 Hz logger whose clock wanders,
a worn or dirty track, a loose connector: the position signal then carries a component whose
increments are close to white (a random walk at the log's rate). The noise estimate (second
differences: white noise on the position) sees little of it, so the record sits far below the
velocity channel's noise ceiling; and the model cannot follow it. Bank effects fitted to it gain a
few points of angle each, about as much as one another, and one of them would be named.

A misfit of the joint's motion (an effect the model leaves out, a parameter off) comes through the
joint's inertia and the command: its velocity residual is coloured over the motion's time scale
(at the residual tests' 75 ms decimation, an 8 Hz mode the model lacks correlates -0.74 from one
sample to the next, a command logged ten times slower than its controller +0.85). So the velocity
channel missing its noise ceiling by far (decision.far: more than FAR_POINTS below it, and a misfit
of more than FAR_NOISE noises) while its residual is white is said as a cause in the record, ahead
of the others, and decision.unexplained_reasons keeps any effect from being named on it. White here
is a size, not a test: no autocorrelation of the decimated velocity residual beyond WHITE_RHO over
its first 20 lags, so at most about that share of it is coloured. The Ljung-Box test finds a
coloured share of a few percent in a 60 s record (the model's own small misfit beside the
disturbance: |rho| up to 0.18, p = 0.004 under 60 mV of hum on the rotary rig), which does not make
the far misfit the motion's.
"""

from __future__ import annotations

import math

import numpy as np

from .decision import FAR_MARK, WHITE_MISS_CHANNELS, far_channels, misfit_in_noise

WHITE_RHO = 0.3   # largest |autocorrelation| (lags 1-20, decimated) of a velocity residual that counts as white


def found(channel_fits: dict[str, dict[str, float]], channel_ceilings: dict[str, dict[str, float]],
          tests: dict[str, dict]) -> dict[str, dict]:
    """Per joint whose velocity channel (``channel_fits``, percent, against ``channel_ceilings``)
    misses its noise ceiling by far (decision.far) while its residual is white
    (``tests``: diagnosis.residual_tests of the same model, with its ``autocorrelation``):
    {'channels': [(channel, fit, ceiling)], 'largest_autocorrelation'}."""
    out: dict[str, dict] = {}
    for j, ch, f, c in far_channels(channel_fits, channel_ceilings, WHITE_MISS_CHANNELS):
        rho = np.asarray(tests.get(j, {}).get("autocorrelation", []), dtype=float)
        largest = float(np.max(np.abs(rho))) if rho.size else math.inf
        if not largest <= WHITE_RHO:
            continue
        out.setdefault(j, {"channels": [], "largest_autocorrelation": largest})["channels"].append((ch, float(f), float(c)))
    return out


def cause(joint: str, finding: dict) -> str:
    """The record cause for one joint of :func:`found`."""
    chans = ", ".join(f"{ch} fit {f:.1f} is {c - f:.1f} points below its noise ceiling {c:.1f} (a misfit of "
                      f"{misfit_in_noise(f, c):.1f} noises)" for ch, f, c in finding["channels"])
    return (f"the position of {joint} carries a disturbance no motion of the joint makes: its {chans} ({FAR_MARK}), "
            f"and the velocity residual is white (no autocorrelation beyond {finding['largest_autocorrelation']:.2f}) "
            "where a misfit of the motion, driven through the joint's "
            "inertia, is coloured. Interference on the sensor's wiring aliased by the logger (mains hum sampled near "
            "50 Hz), a worn or dirty potentiometer track or a loose connector do this. Shield the sensor's cable or "
            "filter it before the logger (an anti-alias filter below half the log's rate) and record again; the "
            "effects tried on this record are the closest, not its cause")
