"""A joint held at the record's extreme while its command drives it further.

Under closed-loop control a joint that does not follow its command is blocked: by an end stop the
robot's spec does not have there (a stroke longer on paper than on the rig), by a sensor at the end
of its range (the joint moves on, the reading does not), or by a load or friction the valve cannot
overcome. The model cannot follow those samples, and a diagnosis would otherwise spend an effect
(a wider deadband, a lower flow) on them. Found from the record alone: the position stays within
its noise of its largest (or smallest) value for runs of at least ``MIN_RUN_S`` while the command
stays beyond ``PUSH_SHARE`` of its range in the direction that moves the joint there (the sign of
the command's correlation with the motion). At a limit the spec already has, it is the model's own
end stop and nothing is reported.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import median_filter

MIN_RUN_S = 0.3            # s: shorter flat runs are a reversal, not a block
PUSH_SHARE = 0.2           # of the command range: a command this large moves a free joint
MIN_SHARE = 0.01           # of the samples held, to be reported
MIN_HELD_S = 1.0           # s held in all, to be reported
MIN_DIRECTION_CORR = 0.1   # |corr(command, motion)| below this: the direction is unknown, nothing is said


def find(time: np.ndarray, y: np.ndarray, u: np.ndarray, noise: float, command_range: tuple[float, float],
         limits: tuple[float, float], margin: float) -> dict | None:
    """Where the joint (position ``y`` in its SI unit, command ``u`` in V) is held at the record's
    extreme while its command pushes it further; ``limits``: the spec's joint range (an extreme within
    ``margin`` of it is the model's end stop). Returns {'side', 'value', 'share', 'runs',
    'longest_s', 'seconds', 'largest_command_v', 'limit' (the spec's, None where it has none)} of the
    side held longest, or None."""
    y, u, time = np.asarray(y, float), np.asarray(u, float), np.asarray(time, float)
    n = y.size
    if n < 10 or u.size != n:
        return None
    y = median_filter(y, size=5, mode="nearest")   # a noise spike neither sets the extreme nor breaks a run
    dt = float(np.median(np.diff(time)))
    dy = np.diff(y)
    push = PUSH_SHARE * max(abs(command_range[0]), abs(command_range[1]))
    with np.errstate(invalid="ignore"):
        corr = np.corrcoef(u[:-1], dy)[0, 1] if np.std(u) > 0 and np.std(dy) > 0 else math.nan
    if not math.isfinite(corr) or abs(corr) < MIN_DIRECTION_CORR:
        return None
    sign = 1.0 if corr > 0 else -1.0
    tol = max(4.0 * noise, 1e-3 * float(np.ptp(y)))
    min_run = max(3, int(math.ceil(MIN_RUN_S / dt)))
    best = None
    for side, extreme, toward in (("upper", float(y.max()), 1.0), ("lower", float(y.min()), -1.0)):
        limit = float(limits[1] if side == "upper" else limits[0])
        if math.isfinite(limit) and abs(extreme - limit) <= margin:
            continue
        at = np.abs(y - extreme) <= tol
        held = at & (toward * sign * u >= push)
        edges = np.diff(np.concatenate(([0], held.astype(np.int8), [0])))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        keep = (ends - starts) >= min_run
        if not keep.any():
            continue
        samples = int(np.sum((ends - starts)[keep]))
        seconds = samples * dt
        if samples < MIN_SHARE * n or seconds < MIN_HELD_S:
            continue
        found = {"side": side, "value": extreme, "share": samples / n, "runs": int(keep.sum()),
                 "longest_s": float(np.max(ends - starts) * dt), "seconds": seconds,
                 "largest_command_v": max(float(np.max(np.abs(u[s:e]))) for s, e in zip(starts[keep], ends[keep])),
                 "limit": limit if math.isfinite(limit) else None}
        if best is None or seconds > best["seconds"]:
            best = found
    return best


def _what(found: dict, unit: str) -> str:
    limit = found["limit"]
    spec_has = (f"the spec's {found['side']} limit is {limit:.4g} {unit}" if limit is not None
                else f"the spec has no {found['side']} limit")
    return (f"the position stays at {found['value']:.4g} {unit}, the record's "
            f"{'largest' if found['side'] == 'upper' else 'smallest'} value, for {100 * found['share']:.1f} % of "
            f"the samples ({found['runs']} runs, longest {found['longest_s']:.1f} s) while the command drives it "
            f"further (up to {found['largest_command_v']:.2f} V): the joint is held there by an end stop the "
            f"spec does not have ({spec_has}: check the stroke or range), by the sensor at the end of its range, "
            f"or by a load the valve cannot move")


def note(joint: str, found: dict, unit: str) -> str:
    """The record's note for what :func:`find` found (``unit``: the joint's position unit, m or rad)."""
    return f"{joint}: " + _what(found, unit) + ". The model cannot follow those samples; an effect named to fit them is suspect"


def cause(joint: str, found: dict, unit: str) -> str:
    """The same as a cause of an unexplained misfit (the report's "In the record")."""
    return f"on {joint} " + _what(found, unit) + (": where it is an end stop, give the spec the rig's range (the joint "
                                                "limit in the URDF, the cylinder's stroke) and diagnose again")
