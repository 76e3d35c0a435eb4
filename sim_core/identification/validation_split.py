"""Where a single record's validation part starts.

By default the first ``ESTIMATION_SHARE`` of the record is fitted and the rest validates. A log often
ends with the rig standing still (the test is over, the logger runs on) or starts so (it was started
before the test), and a record of several joints often moves one of them longer than the others (the
operator works one joint on; a leak keeps one creeping under its controller): a part in which a
diagnosed joint's reading never leaves its noise carries nothing to judge that joint's model by.
Validated on such a part, a joint's model that is exactly right fits the noise near 0 %, one a
fraction of a degree off scores thousands of points below, and a clean record reads as unexplained.
So where either part of the default split holds still on a diagnosed joint that moves elsewhere in
the record (``record.holds_still``, the rule a record's commanded joints are checked by), the split
goes where every such joint moves on both sides of it: each joint's motion runs from the first sample
at which it has left the reading it starts at to the last at which it is still away from the one it
ends at (its mean over ``SMOOTH_SAMPLES`` samples by more than ``STILL_SPAN / 2`` noise sigmas: one
sample beyond 5 sigmas of a level read off 5 samples is a noise draw that a record of ten joints
holding for thousands of samples makes likely, and it would put the end of the motion there), and the
split is the sample at which the joint worst served has the largest share of its motion on the side
it is short of, a share of ``ESTIMATION_SHARE`` before and of the rest after counting as full. On a
record of one joint (or of joints that move together) that is ``ESTIMATION_SHARE`` of the motion.
Where even that split leaves a joint under ``LEAST_SERVED`` of its share (one moves only early,
another only late; a joint homed in the first seconds of a record whose others move throughout,
where serving it would leave them seconds to be fitted on), the default split stays, and a note says
which joint is judged on a part in which it holds still: pass a validation record. The still parts
stay in the record: a hold can show a leak's creep, and the other part still has the motion.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

from .metrics import noise_std
from .record import ESTIMATION_SHARE, STILL_SPAN, Record, holds_still

LEVEL_SAMPLES = 5     # samples whose median is the reading a joint starts or ends at
SMOOTH_SAMPLES = 9    # samples averaged before a reading is compared with those (its noise / 3)
LEAST_SERVED = 1 / 3  # of its share on each side, the least a moved split may leave a joint that moves


def joint_motion(q: np.ndarray) -> tuple[int, int] | None:
    """(first, last + 1) sample at which the reading ``q`` is away from its starting, or its ending,
    reading (its mean over ``SMOOTH_SAMPLES``) by more than ``STILL_SPAN / 2`` noise sigmas; None
    where it never is."""
    band = 0.5 * STILL_SPAN * noise_std(q)
    mean = uniform_filter1d(q, SMOOTH_SAMPLES, mode="nearest")
    away_from_start = np.flatnonzero(np.abs(mean - np.median(q[:LEVEL_SAMPLES])) > band)
    away_from_end = np.flatnonzero(np.abs(mean - np.median(q[-LEVEL_SAMPLES:])) > band)
    first = int(away_from_start[0]) if away_from_start.size else q.size
    last = int(away_from_end[-1]) + 1 if away_from_end.size else 0
    return (first, last) if first < last else None


def served(spans: list[tuple[int, int]], s: np.ndarray) -> np.ndarray:
    """At each split ``s`` (samples): the least, over the joints' motion ``spans``, of the share of a
    joint's motion before s over ``ESTIMATION_SHARE`` and of its motion after s over the rest (1 where
    a joint's motion is split in those shares, 0 or less where all of it is on one side)."""
    first, last = (np.array(v, dtype=float) for v in zip(*spans))
    length = last - first
    s = np.asarray(s, dtype=float)[..., None]
    return np.min(np.minimum((s - first) / (ESTIMATION_SHARE * length),
                             (last - s) / ((1.0 - ESTIMATION_SHARE) * length)), axis=-1)


def best_served(spans: list[tuple[int, int]]) -> float:
    """The split (a sample, not rounded) at which ``served`` is largest. The least of rising shares
    meets the least of falling ones where one joint's share before crosses one's share after: the
    best of those crossings (on one joint, ``ESTIMATION_SHARE`` of its motion)."""
    first, last = (np.array(v, dtype=float) for v in zip(*spans))
    rise, fall = ESTIMATION_SHARE * (last - first), (1.0 - ESTIMATION_SHARE) * (last - first)
    # (s - first_i) / rise_i = (last_k - s) / fall_k, for every i, k
    cross = ((first[:, None] * fall[None, :] + last[None, :] * rise[:, None]) / (rise[:, None] + fall[None, :])).ravel()
    return float(cross[np.argmax(served(spans, cross))])


def validation_start(rec: Record, joints: list[str]) -> tuple[int, str, str]:
    """(first validation sample of ``rec``, why it is not the default one, why it is although a part
    of the default split holds still on a joint that moves); ``joints``: the diagnosed ones, "" where
    there is nothing to say. Where a part holds still on a joint that moves, the split is the sample
    at which every moving joint is best served on both sides (``served``), if that serves each at
    least ``LEAST_SERVED``."""
    n = int(round(rec.n * ESTIMATION_SHARE))
    spans = {j: s for j in joints
             if j in rec.angles and not holds_still(rec.angles[j]) and (s := joint_motion(rec.angles[j]))}
    parts = {"estimation": slice(0, n), "validation": slice(n, rec.n)}
    still = {name: [j for j in spans if holds_still(rec.angles[j][part])] for name, part in parts.items()}
    still = {name: js for name, js in still.items() if js}
    if not still:
        return n, "", ""
    best = best_served(list(spans.values()))
    moved = min(max(int(round(best)), 0), rec.n - 1)
    share, default = served(list(spans.values()), [best, n])
    t = rec.time
    on = {name: ("every diagnosed joint" if len(js) == len(spans) == len([j for j in joints if j in rec.angles])
                 else ", ".join(js)) for name, js in still.items()}
    what = " and ".join(f"the {name} part holds still on {who}" for name, who in on.items())
    default_split = f"the default split (validation from {t[n]:.1f} s, the last {1 - ESTIMATION_SHARE:.0%} of the record)"
    if share < LEAST_SERVED:
        least = f"{LEAST_SERVED * ESTIMATION_SHARE:.0%} and {LEAST_SERVED * (1 - ESTIMATION_SHARE):.0%}"
        return n, "", (f"{what} in {default_split}, and no split serves every joint that moves on both sides: the "
                       f"best, at {t[moved]:.1f} s, leaves one {max(share, 0.0) * ESTIMATION_SHARE:.0%} of its motion "
                       f"before it or {max(share, 0.0) * (1 - ESTIMATION_SHARE):.0%} after (a moved split leaves each at "
                       f"least {least}). The default split stays, and a joint that holds still in a part is judged "
                       f"there on its noise: pass --validation OTHER.csv, a record in which every joint moves")
    if share <= default or not 0 < moved < rec.n:
        return n, "", ""
    first, last = min(f for f, _ in spans.values()), max(e for _, e in spans.values())
    where = (f"{ESTIMATION_SHARE:.0%} into the motion" if len(spans) == 1 else
             f"where each joint that moves has at least {min(share, 1.0) * ESTIMATION_SHARE:.0%} of its motion "
             f"before and {min(share, 1.0) * (1 - ESTIMATION_SHARE):.0%} after")
    return moved, (f"{what} in {default_split}: the joints move from {t[first]:.1f} s to {t[last - 1]:.1f} s, so "
                   f"validation starts at {t[moved]:.1f} s, {where} (or pass --validation OTHER.csv)"), ""
