"""Where a single record's validation part starts.

By default the first ``ESTIMATION_SHARE`` of the record is fitted and the rest validates. A log often
ends with the rig standing still (the test is over, the logger runs on) or starts so (it was started
before the test): a part in which no diagnosed joint's reading leaves its noise carries nothing to
judge a model by. Validated on such a part, a model that is exactly right fits the noise near 0 %,
one a fraction of a degree off scores thousands of points below, and a clean record reads as
unexplained. So where either part of the default split holds still on every diagnosed joint
(``record.holds_still``, the rule a record's commanded joints are checked by), the split is put at
``ESTIMATION_SHARE`` of the record's motion instead: from the first sample at which any joint has
left the reading it starts at, to the last at which any is still away from the one it ends at (its
mean over ``SMOOTH_SAMPLES`` samples by more than ``STILL_SPAN / 2`` noise sigmas: one sample
beyond 5 sigmas of a level read off 5 samples is a noise draw that a record of ten joints holding
for thousands of samples makes likely, and it would put the end of the motion there). The still
parts stay in the record: a hold can show a leak's creep, and the other part still has the motion.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

from .metrics import noise_std
from .record import ESTIMATION_SHARE, STILL_SPAN, Record, holds_still

LEVEL_SAMPLES = 5     # samples whose median is the reading a joint starts or ends at
SMOOTH_SAMPLES = 9    # samples averaged before a reading is compared with those (its noise / 3)


def motion_span(rec: Record, joints: list[str]) -> tuple[int, int]:
    """(first, last + 1) sample at which any of ``joints`` is away from its starting, or its ending,
    reading (its mean over ``SMOOTH_SAMPLES``) by more than ``STILL_SPAN / 2`` noise sigmas; (0, n)
    where none moves."""
    first, last = rec.n, 0
    for j in joints:
        q = rec.angles[j]
        band = 0.5 * STILL_SPAN * noise_std(q)
        mean = uniform_filter1d(q, SMOOTH_SAMPLES, mode="nearest")
        away_from_start = np.flatnonzero(np.abs(mean - np.median(q[:LEVEL_SAMPLES])) > band)
        away_from_end = np.flatnonzero(np.abs(mean - np.median(q[-LEVEL_SAMPLES:])) > band)
        if away_from_start.size:
            first = min(first, int(away_from_start[0]))
        if away_from_end.size:
            last = max(last, int(away_from_end[-1]) + 1)
    return (first, last) if first < last else (0, rec.n)


def validation_start(rec: Record, joints: list[str]) -> tuple[int, str]:
    """First validation sample of ``rec`` (``joints``: the diagnosed ones) and why it is not the
    default one ("" where it is); where the default split leaves a part that holds still, the sample at
    ``ESTIMATION_SHARE`` of the motion."""
    n = int(round(rec.n * ESTIMATION_SHARE))
    joints = [j for j in joints if j in rec.angles]
    parts = {"estimation": slice(0, n), "validation": slice(n, rec.n)}
    still = [name for name, part in parts.items()
             if joints and all(holds_still(rec.angles[j][part]) for j in joints)]
    if not still:
        return n, ""
    first, last = motion_span(rec, joints)
    moved = first + int(round((last - first) * ESTIMATION_SHARE))
    if moved == n or not 0 < moved < rec.n:
        return n, ""
    t = rec.time
    return moved, (f"the {' and the '.join(still)} part{'s' if len(still) > 1 else ''} of the default split "
                 f"(validation from {t[n]:.1f} s, the last {1 - ESTIMATION_SHARE:.0%} of the record) "
                 f"hold{'' if len(still) > 1 else 's'} still on every diagnosed joint: the joints move from "
                 f"{t[first]:.1f} s to {t[last - 1]:.1f} s, so validation starts at {t[moved]:.1f} s, "
                 f"{ESTIMATION_SHARE:.0%} into the motion (or pass --validation OTHER.csv)")
