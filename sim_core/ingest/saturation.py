"""Converter saturation: samples stuck at a channel's full scale, where the true value is unknown.

Full scales are recognised, not guessed from a flat top (a quantised position held still repeats
its value too): raw counts (``*SCALE+OFFSET`` columns, integer-valued) at the ends of an 8- to 24-bit
converter (unsigned 0 .. 2^n-1 or signed -2^(n-1) .. 2^(n-1)-1) and a ``sensor_volts`` column at the
ends of the sensor's input range (within half a per mille of the span).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .runs import runs
from .units import Unit

BITS = (8, 10, 12, 14, 16, 18, 20, 24)
RANGE_TOLERANCE = 5e-4     # share of the sensor span: a reading this close to a range end is at it


@dataclass
class Saturation:
    """Samples of one column at a converter's full scale."""

    full_scale: tuple[float, float]   # raw units
    converter: str                    # '12-bit counts', 'sensor range 0..10 V'
    samples: int
    runs: int
    longest_run: int
    first_row: int                    # from 1, in the file
    rows: list[tuple[int, int]] = field(default_factory=list)  # (first, last) row of each run, from 1

    def to_dict(self) -> dict:
        d = asdict(self)
        d["rows"] = [list(r) for r in self.rows]
        return d


def full_scale(raw: np.ndarray, unit: Unit) -> tuple[tuple[float, float], str] | None:
    """The converter's (low, high) full scale in raw units, when one is recognised."""
    if unit.sensor_range is not None:
        lo, hi = unit.sensor_range
        return (lo, hi), f"sensor range {lo:g}..{hi:g} V"
    if not unit.counts or raw.size == 0 or not np.all(raw == np.round(raw)):
        return None
    lo, hi = float(raw.min()), float(raw.max())
    for n in BITS:
        if lo >= 0 and hi == 2.0 ** n - 1:
            return (0.0, hi), f"{n}-bit counts"
        if lo < 0 and (hi == 2.0 ** (n - 1) - 1 or lo == -(2.0 ** (n - 1))):
            return (-(2.0 ** (n - 1)), 2.0 ** (n - 1) - 1), f"{n}-bit signed counts"
    return None


def find_saturation(raw: np.ndarray, unit: Unit) -> tuple[Saturation, np.ndarray] | None:
    """Where ``raw`` sits at a recognised full scale (report, boolean mask); None if nowhere or no full
    scale is known."""
    fs = full_scale(raw, unit)
    if fs is None:
        return None
    (lo, hi), what = fs
    tol = RANGE_TOLERANCE * (hi - lo) if unit.sensor_range is not None else 0.0
    at = (raw <= lo + tol) | (raw >= hi - tol)
    if not at.any():
        return None
    found = runs(at)
    sat = Saturation((lo, hi), what, int(at.sum()), len(found), max(b - a + 1 for a, b in found), found[0][0] + 1,
                     [(a + 1, b + 1) for a, b in found[:20]])
    return sat, at
