"""Does the record move as fast per volt as the model can? The logged command's scale against the valve's.

A valve meters flow, so a joint's speed follows its command, and the calibration fits the valve's
flow gain within its range. A command logged in another scale than the valve saw (a 0..1 fraction of
the amplifier's +-10 V, a controller output in volts before an amplifier's gain, millivolts read as
volts) leaves the record's joint moving many times faster per logged volt than any calibrated flow
gain lets the model move, and no effect of the bank makes a joint faster than its valve (friction,
leaks, deadbands, flow limits and loads all take speed away). So the record stays unexplained; this
check says why and replays the fix.

Evidence per joint: which way and how fast it moves per volt of command (``closed_loop.direction``),
for the record and for the baseline model driven by the same command. Flagged where both move the
same way (each correlation at least ``polarity.CORRELATION_MIN``) and the record moves more than
``SCALE_LIMIT`` times faster per volt than the model. A record moving slower is not flagged: a stalled
or loaded joint does that too. The fix is replayed on the baseline model and reported with the fit it
gives: the command scaled by that ratio, or, where that would take it beyond the joint's command range
or the ratio is within ``FULL_SCALE_SHARE`` of it, by the factor that maps the logged command's
largest value onto the range's end (a closed loop drives its valve to the end of the range, and the
ratio also carries what the model's flow gain is off by).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..dataset import column_unit
from .polarity import CORRELATION_MIN, evidence, fit_text, points, replay_fit
from .record import Record

# how many times faster per volt the record must move than the calibrated model: a flow gain off its
# datasheet, a valve asymmetry or a null offset moves a calibrated model's speed by tens of percent
SCALE_LIMIT = 3.0
FULL_SCALE_SHARE = 0.3    # a ratio this close to the logged command's full-scale factor is read as it


def factor(k: float, u, command_range) -> float:
    """The scale to read the command with: the ratio ``k``, or the factor mapping the logged command's
    largest magnitude onto the end of ``command_range`` where ``k`` would take it beyond or lies within
    FULL_SCALE_SHARE of it."""
    top = max(abs(float(command_range[0])), abs(float(command_range[1])))
    peak = float(np.max(np.abs(u))) if len(u) else 0.0
    if peak <= 0.0:
        return k
    full = top / peak
    return full if k * peak > top or abs(k / full - 1.0) <= FULL_SCALE_SHARE else k


def ratio(record: dict, model: dict) -> float | None:
    """How many times faster per volt the record moves than the model, where both move with their
    command the same way (each correlation at least CORRELATION_MIN); else None."""
    r, m = record["correlation"], model["correlation"]
    if abs(r) < CORRELATION_MIN or abs(m) < CORRELATION_MIN or (r > 0) != (m > 0) or model["speed_per_volt"] == 0.0:
        return None
    return record["speed_per_volt"] / model["speed_per_volt"]


def too_fast(k: float | None) -> bool:
    """Whether the record moves faster per volt than a calibrated flow gain can explain."""
    return k is not None and k > SCALE_LIMIT


def check(spec, rec: Record, runner, n: int, start: int, base_out, joints: list[str]) -> dict:
    """The scale check on the first ``n`` samples; for each flagged joint, the validation angle fit
    (points, samples ``start``..``n``) as recorded and with the command scaled (:func:`factor`), replayed
    on the baseline model ``spec``. {} when no joint is flagged."""
    found = {}
    for j, e in evidence(rec, base_out, spec, joints, n).items():
        r, m = e["record"], e["model"]
        k = ratio(r, m)
        if not too_fast(k):
            continue
        rng = spec.joint(j).command_range
        f = factor(k, rec.u(j), rng)
        U = rec.U.copy()
        U[:, rec.joint_names.index(j)] *= f
        scaled = runner.simulate(spec, n, rec=replace(rec, U=U))
        found[j] = {"record_speed_per_volt": float(f"{r['speed_per_volt']:.6g}"),
                    "model_speed_per_volt": float(f"{m['speed_per_volt']:.6g}"), "ratio": round(k, 4),
                    "factor": float(f"{f:.4g}"), "fit": points(replay_fit(rec, j, base_out, start, n)),
                    "fit_command_scaled": points(replay_fit(rec, j, scaled, start, n))}
    if not found:
        return {}
    return {"joints": found, "rule": (f"the record moves more than {SCALE_LIMIT:g} times faster per volt of command than "
                                      f"the calibrated model (both with their command, each correlation at least "
                                      f"{CORRELATION_MIN:g})")}


def causes(result: dict, spec) -> list[str]:
    """What to check in the record or the spec, one sentence per flagged joint."""
    lines = []
    for j, e in (result or {}).get("joints", {}).items():
        unit = column_unit(f"q_{j}", spec)
        k, f = e["ratio"], e["factor"]
        lines.append(
            f"on {j} the recorded joint moves {k:.3g} times faster per volt of command than the calibrated model "
            f"(record {e['record_speed_per_volt']:+.3g} {unit}/s per V, model {e['model_speed_per_volt']:+.3g}), and no "
            f"effect makes a joint faster than its valve: the command is logged in another scale than the valve saw "
            f"(a 0..1 fraction or a controller output before its amplifier's gain, another unit), or the valve is "
            f"larger than the spec's (joints.{j}.valve.rated_flow and its [estimated] range). Validation fit "
            f"{fit_text(e['fit'])} as recorded, {fit_text(e['fit_command_scaled'])} with the command scaled by {f:.4g}"
            + ("" if f == k else " (its largest value onto the end of the command range)")
            + f". Read the command scaled (`--column u_{j}=SOURCE:*{f:.4g}`, or by the amplifier's known factor)")
    return lines
