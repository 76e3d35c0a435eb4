"""Where does the record's joint stand still? The command's zero against the valve's null.

A spec puts each valve's null at 0 V of command: a positive command opens it one way, a negative one
the other. Many controllers drive their valve with a unipolar output (0..10 V, or 4..20 mA on a
resistor) whose null is mid-range; logged as it is, that command sits volts away from the model's
null at every sample, far beyond what a valve's null offset can be (the bank's ``valve_offset``
searches +-15 % of the largest command), and the model, fed 5 V where the rig stood still, runs
into an end stop. No parameter or effect of the bank explains that, so the record stays
unexplained; this check says why and replays the fix.

Evidence per joint: the command where the recorded joint stands still (its smoothed speed below
``STILL_SPEED`` of its 95th-percentile speed, away from its end stops, the command inside its range).
In closed loop that is the controller holding the joint: at the valve's null plus what holding it
takes (a leak, a null offset, a load through a deadband). On the three templates' records (seed 2)
the median sits within +-0.25 V of 0 V, a 0.25 V null offset's at -0.25 V, and with a 0.8 V
deadband within +-0.8 V, its 10-90 % span straddling 0 V (the controller stops anywhere inside the
deadband). Flagged where the whole 10-90 % span of those commands lies beyond the valve offset's
bound on one side (a wide deadband straddles the null; a unipolar output sits tightly off it) and
the joint stands still on at least ``MIN_STILL`` of the samples. The fix, the command shifted by
their median, is replayed on the baseline model.
"""

from __future__ import annotations

import math

import numpy as np

from ..effects.valve_offset import SPAN
from .closed_loop import unsaturated
from .metrics import velocity
from .polarity import fit_text, points, replay_fit, with_command
from .record import END_STOP_MARGIN, Record

STILL_SPEED = 0.02        # share of the joint's 95th-percentile speed below which it stands still
MIN_STILL = 0.05          # share of the samples the joint must stand still on for the median to count
MID_RANGE = 0.1           # |null - max/2| within this share of max: a unipolar output nulled mid-range


def rest_command(u: np.ndarray, q: np.ndarray, dt: float, command_range, limits=None) -> dict | None:
    """The command where the joint stands still: median, 10th and 90th percentiles (V) and the share of
    samples it stands still on; None where it never does (or never moves)."""
    u, q = np.asarray(u, float), np.asarray(q, float)
    if u.size < 10:
        return None
    v = np.abs(velocity(q, dt))
    fast = float(np.percentile(v, 95))
    if not fast > 0.0:
        return None
    still = (v < STILL_SPEED * fast) & unsaturated(u, command_range)
    if limits is not None:
        lo, hi = limits
        if math.isfinite(lo):
            still &= q > lo + END_STOP_MARGIN
        if math.isfinite(hi):
            still &= q < hi - END_STOP_MARGIN
    if not still.any():
        return None
    p10, med, p90 = np.percentile(u[still], [10, 50, 90])
    return {"median": float(med), "p10": float(p10), "p90": float(p90), "still_share": float(still.mean())}


def bound(command_range) -> float:
    """The largest null offset (V) the bank's ``valve_offset`` names for a joint with this range."""
    lo, hi = command_range
    return SPAN * max(abs(lo), abs(hi))


def off_null(rest: dict | None, command_range) -> bool:
    """Whether the joint stands still at commands beyond any valve null offset: its 10-90 % span of
    them wholly on one side, past the bound."""
    if rest is None or rest["still_share"] < MIN_STILL:
        return False
    b = bound(command_range)
    return rest["p10"] > b or rest["p90"] < -b


def read_as(null: float, u: np.ndarray, command_range) -> list[str]:
    """``--column`` units that put the valve's null at 0 V: the shift, and for a unipolar output
    (never below 0 V) nulled mid-range also its map onto the spec's range (0..10 V onto -10..10 V:
    ``*2-10``)."""
    out = [f"*1{-null:+.4g}"]
    lo, hi = float(np.min(u)), float(np.max(u))
    top = float(command_range[1])
    if lo >= 0.0 and hi > 0.0 and abs(null - hi / 2.0) <= MID_RANGE * hi:
        out.append(f"*{2.0 * top / hi:.4g}{-top:+.4g}")
    return out


def check(spec, rec: Record, runner, n: int, start: int, base_out, joints: list[str]) -> dict:
    """The null check on the first ``n`` samples; for each flagged joint, the validation angle fit
    (points, samples ``start``..``n``) as recorded and with the command shifted by its rest median,
    replayed on the baseline model ``spec``. {} when no joint is flagged."""
    found = {}
    for j in joints:
        rng = spec.joint(j).command_range
        i = spec.tree.index(spec.joint(j).dof)
        rest = rest_command(rec.u(j)[:n], rec.angles[j][:n], rec.dt, rng,
                            (float(spec.tree.lower[i]), float(spec.tree.upper[i])))
        if not off_null(rest, rng):
            continue
        shifted = runner.simulate(spec, n, rec=with_command(rec, j, shift=-rest["median"]))
        found[j] = {**{k: round(v, 4) for k, v in rest.items()}, "bound_v": round(bound(rng), 4),
                    "read_as": read_as(rest["median"], rec.u(j), rng),
                    "fit": points(replay_fit(rec, j, base_out, start, n)),
                    "fit_command_shifted": points(replay_fit(rec, j, shifted, start, n))}
    if not found:
        return {}
    return {"joints": found, "rule": (f"the median command where the joint stands still (speed below {STILL_SPEED:g} of "
                                      f"its 95th percentile, on at least {MIN_STILL:.0%} of the samples): its 10-90 % span "
                                      f"lies wholly beyond the valve null offset the bank can name ({SPAN:.0%} of the "
                                      f"largest command), on one side")}


def causes(result: dict) -> list[str]:
    """What to check in the record, one sentence per flagged joint."""
    lines = []
    for j, e in (result or {}).get("joints", {}).items():
        c = e["median"]
        said = (f"on {j} the joint stands still at a command of {c:+.3g} V (median over the {100 * e['still_share']:.0f} % "
                f"of the samples where it does, 10-90 % {e['p10']:+.3g} .. {e['p90']:+.3g} V), where the model's valve "
                f"is closed at 0 V and a valve's null offset is within +-{e['bound_v']:.3g} V: the command's zero is not "
                f"the valve's null. Validation fit {fit_text(e['fit'])} as recorded, {fit_text(e['fit_command_shifted'])} "
                f"with the command shifted by {-c:+.3g} V. Read the command shifted (`--column u_{j}=SOURCE:{e['read_as'][0]}`)")
        if len(e["read_as"]) > 1:
            said += (f", or, if it comes from a unipolar output (0 .. 10 V) whose null is mid-range, mapped onto the "
                     f"spec's command range (`--column u_{j}=SOURCE:{e['read_as'][1]}`)")
        lines.append(said)
    return lines
