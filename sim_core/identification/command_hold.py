"""What the valve saw between two logged samples of a closed-loop command: held, or moving.

A controller that runs at its log's rate holds each command it logs until the next: replaying the
logged samples held (zero-order hold) is exact. A controller faster than its logger (a 1 kHz PLC
logged at 50 Hz) moves its command between the samples: under ``u = K (r - y)`` the command falls
as the joint closes on the set point, and a set point that steps between two samples acts from
the step, not from the next sample. The held replay then lags the command by about half a period
on average (more at each step), which no parameter of the rig stands for; it reads as a slower
valve, an asymmetry or a delay.

The mean of the command over one period is what integrates into the joint's motion. Under a P or
PI law the command is linear in the position and in the slowly moving integral, so over a period
in which the set point holds its mean is the mean of the two samples that bound it; over a period
in which the set point steps, that mean is the expected one for a step anywhere within it. So
the second replay holds, over each period, the mean of the samples at its two ends.

Which of the two the record was taken with is decided by the record: the baseline is calibrated
on each (one calibrated on the other's replay is biased towards it), and the period mean is kept
when its velocity fit on the closed-loop joints is better by ``MARGIN_POINTS`` and by ``SHARE_PCT`` of the held replay's misfit (the velocity channel, not the angle: a held replay's lag is a local
error, while an open-loop replay integrates any error into the angle). On the rigs' closed-loop
records the truth model's velocity fit differs by 1.6 to 10 points between the replays, the right
one always ahead. ``diagnose --command-hold`` gives the choice instead.

The baseline's choice can be swayed by what the baseline lacks: a large effect it misses (a flow
limit clips the speeds a step asks for, and the period mean smooths the steps) moves the two fits
by more than the hold does. So once effects are named, the named model is refitted on the other
replay (below); where it then scores better on the validation data by more than a tie (``REVISIT_POINTS``), the
diagnosis is run again with the other replay, and the answer whose model fits the validation data
better is the one given (``revisited`` in ``closed_loop_evidence.command_hold``).

A pure delay in the rig trades against the hold: half a period of it makes the held replay of a
faster controller fit as well as the period mean. So each effect named on a closed-loop record is
refitted with the command replayed the other way (``if_command_hold``), and where the two tie its
value there is said beside the named one (:func:`describe`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .closed_loop import HELD_REPLAY
from .decision import EXCHANGE_POINTS
from .record import Record

# velocity fit (points) the period mean must gain over the held replay: under the 1.6 by which the
# right replay led on the templates' clean logs of a fast loop, over the 0.3 an unnamed effect's
# misfit moved the two on a log-rate loop's record (the rig's area ratio in the scored matrix)
MARGIN_POINTS = 1.0
# ... and the share of the held replay's velocity misfit it must remove: a baseline that lacks a
# large effect misses the velocity by tens of points, and either replay moves that by a few percent
# (an area ratio 2 %, a flow limit 3.5 %, a 0.8 V deadband 1 % on the templates and the matrix's rig);
# the right period mean removed 17-43 % on the templates' clean logs of a fast loop
SHARE_PCT = 10.0
# validation score (points) within which the other replay, refitted, ties with the one used: the
# exchange pass's margin between two models (decision.EXCHANGE_POINTS)
TIE_POINTS = EXCHANGE_POINTS
# ... and by which it must beat the one used for the diagnosis to be run again that way: beyond the
# tie. Where the replay chosen was right, the other scored 0.3-2.9 points worse on the templates'
# logs; the boom's deadband and valve asymmetry under a log-rate loop, replayed as period means by a
# baseline without them, scored 1.96 and 0.91 points better held
REVISIT_POINTS = TIE_POINTS
# an unexplained record is diagnosed again with the other replay unless the baseline's velocity
# misfit there is more than this many times the one used (between the 1.2 of a delay the baseline
# lacks and the 14 of a command logged in another scale)
FAR_RATIO = 2.0

HELD = "held"
PERIOD_MEAN = "period_mean"
AUTO = "auto"
CHOICES = (AUTO, HELD, PERIOD_MEAN)    # diagnose --command-hold
GIVEN_RULE = "given (diagnose --command-hold)"   # the rule of a replay the user chose
REVISED_RULE = ("revisited: the model with the named effects, refitted on each replay, fits the validation data "
                "better with this one by {points:.2f} points (more than the {margin:g} of a tie), where the baseline without them "
                "preferred the other")
UNEXPLAINED_RULE = ("revisited: replayed {first}, which the calibrated baseline preferred, the record was left "
                    "unexplained; diagnosed again this way, it is explained and fits the validation data better by "
                    "more than a tie")

NOTE = ("the command is replayed as the mean of each two logged samples, held over the period between them ({joints}): "
        "{why}. How each move started within its period is not in the log; log the command at the controller's rate")

# Said beside an unexplained verdict when the period mean is replayed (closed_loop.HELD_REPLAY otherwise)
PERIOD_REPLAY = ("the record is closed loop and its controller runs faster than its log: the command is replayed "
                 "as the mean of each two logged samples, the expected command over the period between them, but "
                 "where within a period each reference step came is not in the log, and an open-loop replay carries "
                 "that to the end of the record. Log the command at the controller's rate")


def period_mean(U: np.ndarray, columns: list[int]) -> np.ndarray:
    """``U`` with each of ``columns`` replaced, over each period, by the mean of the samples that
    bound it (the last sample stays: it bounds no period the simulation runs)."""
    out = np.array(U, dtype=float, copy=True)
    for c in columns:
        out[:-1, c] = 0.5 * (U[:-1, c] + U[1:, c])
    return out


def replayed(rec: Record, joints: list[str]) -> Record:
    """``rec`` with the commands of ``joints`` replayed as their period means."""
    return replace(rec, U=period_mean(rec.U, [rec.joint_names.index(j) for j in joints]))


def choose(held: dict[str, dict[str, float]], mean: dict[str, dict[str, float]], joints: list[str],
           given: str = AUTO) -> dict:
    """The replay the record was taken with, from the fits (per joint channel fits, points) of the
    same model on the held and the period-mean replay; ``joints``: the closed-loop ones. ``given``:
    the user's choice ('held', 'period_mean'), which the fits are then only reported beside."""
    vh = float(np.mean([held[j]["velocity"] for j in joints]))
    vm = float(np.mean([mean[j]["velocity"] for j in joints]))
    share = 100.0 * (vm - vh) / (100.0 - vh) if vh < 100.0 else 0.0
    ahead = vm - vh >= MARGIN_POINTS and share >= SHARE_PCT
    out = {"replay": PERIOD_MEAN if ahead else HELD, "joints": list(joints),
           "velocity_fit": {HELD: round(vh, 3), PERIOD_MEAN: round(vm, 3)},
           "misfit_removed_pct": round(share, 1) if np.isfinite(share) else None,
           "margin_points": MARGIN_POINTS, "share_pct": SHARE_PCT,
           "rule": f"the velocity fit on the closed-loop joints of the baseline calibrated on each replay, the "
                   f"command held and as the mean of each two samples; the mean kept when better by "
                   f"{MARGIN_POINTS:g} points and by {SHARE_PCT:g} % of the held replay's misfit"}
    if given != AUTO:
        out.update(replay=given, rule=GIVEN_RULE)
    return out


def other(replay: str) -> str:
    """The replay that is not ``replay``."""
    return HELD if replay == PERIOD_MEAN else PERIOD_MEAN


def revisit(hold: dict, score_points: float | None, unexplained: bool = False) -> str | None:
    """The replay to diagnose the record again with, where the record chose the replay (not the user,
    not a revisit already) and either the named model refitted on the other one (``score_points``:
    its validation score against the one used) beats it by more than ``REVISIT_POINTS``, or the record
    is left ``unexplained`` where the calibrated baseline's velocity misfit on the other is within
    ``FAR_RATIO`` times its misfit on the one used; None otherwise. An effect the baseline lacks
    moves the two misfits apart by a share (a 60 ms delay under a 1 kHz loop: 39 and 46 points); a
    baseline that misses many times more on the other replay has gone astray there for a cause that
    is not the hold (a command logged a fifth of its scale: 6 and 79 points), and the record's
    cause lies elsewhere."""
    if hold.get("rule") == GIVEN_RULE or "revisited" in hold:
        return None
    there = other(hold["replay"])
    fits = hold["velocity_fit"]
    if unexplained and 100.0 - fits[there] <= FAR_RATIO * (100.0 - fits[hold["replay"]]):
        return there
    if score_points is not None and score_points > REVISIT_POINTS:
        return there
    return None


def adopt(first_score: float, second_score: float, first_unexplained: bool, second_unexplained: bool) -> bool:
    """Whether the second diagnosis (the other replay) is the answer: it fits the validation data at
    least as well (points), and where the first left the record unexplained, it explains it and
    fits better by more than a tie; an explained answer is not given up for an unexplained one."""
    if second_unexplained and not first_unexplained:
        return False
    if first_unexplained:
        return not second_unexplained and second_score > first_score + TIE_POINTS
    return second_score >= first_score


def revisited(hold: dict, first: dict, gain: float | None) -> dict:
    """``hold`` (the second diagnosis's, given the other replay) with the rule that chose it and what
    the first diagnosis had: its replay and the named model's gain from this replay (points; None:
    the first left the record unexplained). The validation scores of both answers (``score_points``)
    and the replay whose answer is given (``answer``) are added once both are known."""
    rule = (REVISED_RULE.format(points=gain, margin=REVISIT_POINTS) if gain is not None
            else UNEXPLAINED_RULE.format(first=first["replay"].replace("_", " ")))
    return dict(hold, rule=rule, revisited=revisit_entry(first["replay"], gain))


def revisit_entry(first_replay: str, gain: float | None) -> dict:
    """``revisited``'s first keys: the first diagnosis's replay and its named model's gain from the
    other one (points; None: that diagnosis left the record unexplained)."""
    return {"first_replay": first_replay, "named_model_gain_points": None if gain is None else round(float(gain), 3)}


def kept_note(hold: dict) -> str:
    """The note where the second diagnosis, with the other replay, was not the better answer (the
    first's is given)."""
    r = hold["revisited"]
    again = other(hold["replay"])
    why = ("where the named model fitted {:+.1f} points better".format(r["named_model_gain_points"])
           if r["named_model_gain_points"] is not None else "as the record was left unexplained")
    said = (r.get("verdicts") or {}).get(again)
    return (f"diagnosed again with the command replayed {again.replace('_', ' ')}, {why}; that answer"
            + (f" ({said})" if said else "") + f" was not the better one ({r['score_points'][again]:.1f} against "
            f"{r['score_points'][hold['replay']]:.1f} points of validation fit"
            + (f"; an unexplained record gives way only to an answer that explains it and fits better by more than "
               f"{TIE_POINTS:g}" if r["named_model_gain_points"] is None else "") + f"), so this one stands; where you know "
            f"the controller ran {'faster than' if again == PERIOD_MEAN else 'at'} the log's rate, --command-hold "
            f"{again} gives that answer")


def note(hold: dict) -> str:
    """The report's note on a replay other than holding each sample chosen by the baseline: a
    period-mean replay, or a revisited one."""
    fits = hold["velocity_fit"]
    gain = fits[PERIOD_MEAN] - fits[HELD]
    if "revisited" in hold:
        r = hold["revisited"]
        how = ("held from one logged sample to the next" if hold["replay"] == HELD
               else "as the mean of each two logged samples, held over the period between them")
        first = r["first_replay"].replace("_", " ")
        why = (f"the model with the named effects fits the validation data {r['named_model_gain_points']:+.1f} points "
               f"better that way than replayed {first}, which the calibrated baseline without them preferred"
               if r["named_model_gain_points"] is not None else
               f"replayed {first}, which the calibrated baseline preferred, the record was left unexplained")
        return f"the command is replayed {how} ({', '.join(hold['joints'])}): {why} ({gain:+.1f} points of velocity fit for the period mean)"
    why = (f"the record is fitted {gain:+.1f} points better in velocity that way than holding each sample, as a "
           f"controller faster than its logger makes it" if hold["rule"] != GIVEN_RULE
           else f"as given (--command-hold; {gain:+.1f} points of velocity fit against holding each sample)")
    return NOTE.format(joints=", ".join(hold["joints"]), why=why)


def said(hold: dict) -> str:
    """What the diagnosis says of its replay: the note of a period-mean or revisited one, or that a
    second diagnosis the other way fitted worse."""
    r = hold.get("revisited")
    if r and r.get("answer") == r["first_replay"]:
        return kept_note(hold)
    return note(hold)


def cause(loop: dict) -> str | None:
    """What an unexplained closed-loop record's replay of its command leaves out, for its causes in
    the record (``loop``: closed_loop.detect's answer with the ``command_hold`` the diagnosis chose;
    None: open loop)."""
    if not loop.get("closed_loop"):
        return None
    if loop.get("command_hold", {}).get("replay") == PERIOD_MEAN:
        return PERIOD_REPLAY
    return HELD_REPLAY


def describe(item: dict) -> list[str]:
    """The line ``diagnose`` prints under a named effect (a diagnosis.json ``selected`` item) whose
    values move beyond their 95 % intervals when the command is replayed the other way, where that
    replay, refitted, scores within ``TIE_POINTS`` of the one used (the record does not tell the two
    apart: a delay trades half a period against the hold); [] otherwise."""
    other = item.get("if_command_hold")
    if not other or other.get("score_points") is None or other["score_points"] < -TIE_POINTS:
        return []
    moved = {k: v for k, v in other["params"].items()
             if v is not None and k in item["ci95"] and not item["ci95"][k][0] <= v <= item["ci95"][k][1]}
    if not moved:
        return []
    how = ("held from one logged sample to the next (a controller at the log's rate)" if other["replay"] == HELD
           else "as the mean of each two logged samples (a controller faster than its log)")
    return [f"with the command replayed {how}: {', '.join(f'{k}={v:.4g}' for k, v in moved.items())} "
            f"(the record does not tell which; --command-hold {other['replay']})"]
