"""A position against its joint's range: how much of it lies outside, and which unit would put it inside.

The joint cannot leave its range (the URDF's limits are end stops), so samples further outside it
than an end-stop overshoot (``MARGIN``) are read in another unit or scale than they were logged in.
The import notes them with the units under which the raw values lie inside (:func:`readings_inside`);
the diagnosis names them (identification/outside_range.py).
"""

from __future__ import annotations

import math

import numpy as np

from .units import Unit

MARGIN = 0.1            # rad (m on a prismatic joint): further outside the range is no end-stop overshoot
INSIDE_SHARE = 0.99     # of the samples a reading must put inside a joint's range to be suggested
SPAN_SHARE = 0.05       # of the range the reading must span (any column read small enough lies inside)


def share(y, lo: float, hi: float) -> float:
    """The share of the positions ``y`` further than MARGIN outside [lo, hi] (0 without finite limits)."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return 0.0
    y = np.asarray(y, float)
    return float(np.mean((y < lo - MARGIN) | (y > hi + MARGIN))) if y.size else 0.0


def readings_inside(raw, readings: dict[str, Unit], lo: float, hi: float) -> list[str]:
    """Of ``readings`` (a unit's text -> its Unit), those under which the ``raw`` values lie inside
    [lo - MARGIN, hi + MARGIN] on at least INSIDE_SHARE of the samples and span at least SPAN_SHARE of
    the range: the units a position that lies outside its joint's range was most likely logged in."""
    raw = np.asarray(raw, float)
    raw = raw[np.isfinite(raw)]
    out = []
    if not len(raw) or not hi > lo:
        return out
    for text, unit in readings.items():
        v = unit.convert(raw)
        inside = np.mean((v >= lo - MARGIN) & (v <= hi + MARGIN))
        if inside >= INSIDE_SHARE and float(np.ptp(v)) >= SPAN_SHARE * (hi - lo):
            out.append(text)
    return out
