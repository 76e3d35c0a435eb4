"""A disturbance on the measured position that no motion of the joint makes.

Mains hum picked up by a potentiometer's wiring and sampled by a 50 Hz logger whose clock wanders,
a worn or dirty track, a loose connector: the position signal then carries a component whose
increments are close to white (a random walk at the log's rate). The noise estimate (second
differences: white noise on the position) sees little of it, so the record sits far below the
velocity channel's noise ceiling; and the model cannot follow it. Bank effects fitted to it gain a
few points of angle each, about as much as one another, and one of them would be named.

A misfit of the joint's motion (an effect the model leaves out, a parameter off) comes through the
joint's inertia and the command: its velocity residual is coloured over the motion's time scale.
So a channel of the position more than FAR_POINTS below its noise ceiling while the velocity
residual is white (the residual tests' Ljung-Box, at their decimation) is said as a cause in the
record, ahead of the others, and decision.unexplained_reasons keeps any effect from being named on
it.
"""

from __future__ import annotations

from .decision import FAR_POINTS, POSITION_CHANNELS, far_channels

P_WHITE = 0.01   # Ljung-Box p-value at or above which the velocity residual counts as white (residual_fails')


def found(channel_fits: dict[str, dict[str, float]], channel_ceilings: dict[str, dict[str, float]],
          tests: dict[str, dict]) -> dict[str, dict]:
    """Per joint whose position channels (``channel_fits``, percent, against ``channel_ceilings``)
    sit more than FAR_POINTS below their noise ceilings while its velocity residual is white
    (``tests``: diagnosis.residual_tests of the same model): {'channels': [(channel, fit, ceiling)],
    'ljung_box_p'}."""
    out: dict[str, dict] = {}
    for j, ch, f, c in far_channels(channel_fits, channel_ceilings, POSITION_CHANNELS):
        p = tests.get(j, {}).get("ljung_box_p")
        if p is None or not p >= P_WHITE:
            continue
        out.setdefault(j, {"channels": [], "ljung_box_p": float(p)})["channels"].append((ch, float(f), float(c)))
    return out


def cause(joint: str, finding: dict) -> str:
    """The record cause for one joint of :func:`found`."""
    chans = ", ".join(f"{ch} fit {f:.1f} is {c - f:.1f} points below its noise ceiling {c:.1f}"
                      for ch, f, c in finding["channels"])
    return (f"the position of {joint} carries a disturbance no motion of the joint makes: its {chans} (more than "
            f"{FAR_POINTS:g}), and the velocity residual is white (Ljung-Box p = {finding['ljung_box_p']:.2f}) where "
            "a misfit of the motion, driven through the joint's inertia, is coloured. Interference on the sensor's "
            "wiring aliased by the logger (mains hum sampled near 50 Hz), a worn or dirty potentiometer track or a "
            "loose connector do this. Shield the sensor's cable or filter it before the logger (an anti-alias "
            "filter below half the log's rate) and record again; the effects tried on this record are the "
            "closest, not its cause")
