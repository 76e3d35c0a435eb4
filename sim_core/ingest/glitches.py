"""Glitches in a measured position: one to three samples that leave the signal and come back faster
than the joint ever moves.

A potentiometer's wiper lifting off its track, a loose connector or an interference burst reads as a
short excursion (often to 0 V or to the converter's full scale) that the joint cannot have made: it
has inertia, and a position that jumps away and back within a sample or two would need a speed far
beyond anything the rest of the record shows. Left in, four such samples of a 3000-sample log turn
a clean record into an unexplained one (the velocity the fits compare is differentiated from the
position). They are found by how far each sample sits from the running median of its neighbours
(a Hampel identifier: the median follows ramps, reversals and steps, not excursions of at most
:data:`MAX_RUN` samples), and kept only where the excursion is also physically impossible: larger
than :data:`SPEED_FACTOR` times the largest change between two clean neighbouring samples of the
whole record. A hard stop or a reversal moves the signal in steps of the record's own size and is
never taken for a glitch; excursions on more than :data:`MAX_SHARE` of the samples are a property of
the signal (a vibration the sampling aliases), not glitches, and are left alone.

The rule is unit-free (ratios of the signal's own changes), so raw counts, volts and metres give the
same samples; a glitch is repaired by linear interpolation between the clean samples either side.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import median_filter

from .runs import bridged, runs

MAX_RUN = 3            # samples: longer excursions are motion or saturation, not glitches
NOISE_FACTOR = 8.0     # a candidate departs from the running median by more than this many noise sigmas
SPEED_FACTOR = 2.0     # ... and from its clean neighbours by more than this times the record's fastest step
MAX_SHARE = 0.02       # more of the record than this is a property of the signal (a vibration), not glitches
POLICIES = ("repair", "keep", "fail")


@dataclass
class Glitches:
    """Glitch samples of one column (rows from 1, in the order read)."""

    samples: int
    runs: int
    largest: float          # largest departure from the line between the clean neighbours, column units
    fastest_step: float     # largest change between two clean neighbouring samples, column units
    rows: list[tuple[int, int]] = field(default_factory=list)  # (first, last) row of each run, from 1

    @property
    def first_row(self) -> int:
        return self.rows[0][0]

    def to_dict(self) -> dict:
        return {"samples": self.samples, "runs": self.runs, "largest_departure": self.largest,
                "fastest_clean_step": self.fastest_step, "rows": [list(r) for r in self.rows]}


def _noise(y: np.ndarray) -> float:
    """White-noise sigma from second differences (median absolute deviation), floored above zero."""
    d2 = np.diff(y, 2)
    sigma = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / np.sqrt(6.0)
    if sigma > 0.0:
        return sigma
    steps = np.abs(np.diff(y))
    steps = steps[steps > 0]
    return float(steps.min()) / np.sqrt(12.0) if steps.size else 0.0


def find_glitches(y: np.ndarray) -> tuple[Glitches, np.ndarray] | None:
    """The glitches of ``y`` (report, boolean mask of glitch samples), or None when there is none."""
    y = np.asarray(y, dtype=float)
    n = y.size
    if n < 4 * MAX_RUN + 3:
        return None
    departure = np.abs(y - median_filter(y, size=2 * MAX_RUN + 1, mode="mirror"))
    sigma = _noise(y)
    rough = departure > NOISE_FACTOR * sigma          # glitches and the sharpest corners of the motion
    if not rough.any():
        return None
    step = np.abs(np.diff(y))
    clean_pair = ~rough[:-1] & ~rough[1:]
    fastest = float(step[clean_pair].max()) if clean_pair.any() else 0.0
    # a glitch shifts its neighbours' running median by one rank (one step of the motion around it):
    # only departures beyond the fastest step are candidates, so the run is the glitch itself
    candidate = rough & (departure > SPEED_FACTOR * fastest)
    if not candidate.any():
        return None
    mask = np.zeros(n, dtype=bool)
    rows, largest = [], 0.0
    for a, last in runs(candidate):                      # run [a, b)
        b = last + 1
        if b - a > MAX_RUN:
            continue
        if a == 0 or b == n:                              # at an end of the record: one neighbour
            line = np.full(b - a, y[b] if a == 0 else y[a - 1])
            returns = True
        else:
            line = y[a - 1] + (y[b] - y[a - 1]) * (np.arange(a, b) - a + 1) / (b - a + 1)
        off = float(np.max(np.abs(y[a:b] - line)))
        if 0 < a and b < n:
            returns = abs(y[b] - y[a - 1]) < 0.5 * off    # comes back: an excursion, not a step
        if returns and off > SPEED_FACTOR * fastest:
            mask[a:b] = True
            rows.append((int(a) + 1, int(b)))
            largest = max(largest, off)
    if not rows or mask.sum() > MAX_SHARE * n:
        return None
    return Glitches(int(mask.sum()), len(rows), largest, fastest, rows), mask


def repaired(y: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``y`` with the glitch samples under ``mask`` replaced by linear interpolation between the clean
    samples either side (the nearest clean sample at an end of the record)."""
    return bridged(y, mask)
