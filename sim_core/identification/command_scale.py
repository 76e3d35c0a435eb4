"""Does the record move as fast per volt as the spec's valve can? The logged command's scale against the valve's.

A valve meters flow, so a joint's speed follows its command, and the calibration fits the valve's
flow gain within its range. A command logged in another scale than the valve saw (a 0..1 fraction of
the amplifier's +-10 V, a controller output in volts before an amplifier's gain, millivolts read as
volts) leaves the record's joint moving many times faster per logged volt than the spec's valve lets
the model move, and no effect of the bank makes a joint faster than its valve (friction, leaks,
deadbands, flow limits and loads all take speed away). The calibration takes up what its flow gain's
range allows (to its end, with the other parameters pushed to theirs) and the record stays
unexplained; this check says why and replays the fix.

Evidence per joint: which way and how fast it moves per volt of command (``closed_loop.direction``),
for the record and for the calibrated baseline model driven by the same command. Where both move the
same way (each correlation at least ``polarity.CORRELATION_MIN``), the ratio of the two times the
calibrated flow gain's share of the spec's is how many times faster per volt the record moves than
the spec's valve; flagged beyond ``SCALE_LIMIT``. A record moving slower is not flagged: a stalled or
loaded joint does that too. The fix is replayed on the baseline model and reported with the fit it
gives: the command scaled by that ratio, or, where that would take it beyond the joint's command range
or the ratio is within ``FULL_SCALE_SHARE`` of it, by the factor that maps the logged command's
largest value onto the range's end (a closed loop drives its valve to the end of the range, and the
ratio also carries what the spec's flow gain is off by), with the flow gain inside its declared
range (:func:`replayed`).

The same error can instead be absorbed where the record is explained: a rig that declares its valve's
flow gain estimated lets it go beyond its declared range in place of a named effect (beyond_range.py),
by a valve many times larger than the spec's. Such a flow gain, more than ``SCALE_LIMIT`` times the
spec's (or under its inverse), is checked the same way (:func:`flow_gain`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..dataset import column_unit
from .polarity import CORRELATION_MIN, evidence, fit_text, points, replay_fit, with_command
from .polarity import explains as polarity_explains
from .record import Record

# how many times faster per volt the record must move than the calibrated model: a flow gain off its
# datasheet, a valve asymmetry or a null offset moves a calibrated model's speed by tens of percent
SCALE_LIMIT = 3.0
FULL_SCALE_SHARE = 0.3    # a ratio this close to the logged command's full-scale factor is read as it
FLOW_GAIN = ".valve.rated_flow"


@dataclass(frozen=True)
class FlowGain:
    """A joint's valve flow gain (m^3/s): the spec's (``nominal``), the calibrated model's (``value``)
    and the range the calibration may use (``declared``: the spec's [estimated] range, or the
    calibration's own)."""

    key: str
    nominal: float
    value: float
    declared: tuple[float, float]

    @property
    def share(self) -> float:
        """The calibrated flow gain as a share of the spec's."""
        return self.value / self.nominal if self.nominal > 0.0 else 1.0


def flow_gains(spec, model, free) -> dict[str, FlowGain]:
    """Per joint, the flow gain of the spec ``spec`` and of the calibrated ``model``, for the valve flow
    gains among the freed parameters ``free`` (calibration's FreeParameter list; a parameter freed beyond
    its declared range keeps that range as ``declared``)."""
    out = {}
    for fp in free:
        if fp.key.endswith(FLOW_GAIN) and fp.key.count(".") == 3:
            out[fp.key.split(".")[1]] = FlowGain(fp.key, float(fp.get(spec)), float(fp.get(model)),
                                                 tuple(getattr(fp, "declared", (fp.lower, fp.upper))))
    return out


def replayed(model, rec: Record, runner, n: int, start: int, j: str, k: float, flow: FlowGain | None,
             sign: float = 1.0) -> dict:
    """The fix of a record moving ``k`` times faster per volt on joint ``j`` than the spec's valve:
    the scale to read the command with (:func:`factor`; times ``sign``, -1 for a command also logged
    reversed) and the validation angle fit (points, samples
    ``start``..``n``) of ``model`` with the command so scaled and its flow gain (``flow``) at the one of
    two values inside its declared range that replays the record better: the calibrated one (fitted
    beside the model's other parameters) or the rest of ``k`` (what the speeds per volt ask)."""
    f = factor(k, rec.u(j), model.joint(j).command_range)
    scaled = with_command(rec, j, sign * f)
    gains = [None]
    if flow is not None and flow.nominal > 0.0:
        lo, hi = flow.declared
        gains = list(dict.fromkeys(min(max(g, lo), hi) for g in (flow.value, flow.nominal * k / f)))
    best = None
    for gain in gains:
        spec = model.copy()
        if gain is not None:
            spec.set(flow.key, gain)
        fit = replay_fit(rec, j, runner.simulate(spec, n, rec=scaled), start, n)
        if best is None or fit > best[1]:
            best = (gain, fit)
    out = {"factor": float(f"{sign * f:.4g}")}
    if best[0] is not None:
        out.update(flow_gain=float(f"{best[0]:.4g}"), flow_gain_share=round(best[0] / flow.nominal, 4))
    out["fit_command_scaled"] = points(best[1])
    return out


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


def against_spec(record: dict, model: dict, flow: FlowGain | None) -> float | None:
    """How many times faster per volt the record moves than the spec's valve lets the model move: the
    :func:`ratio` to the calibrated model times its flow gain's share of the spec's (``flow``; None: the
    model's is the spec's); None where :func:`ratio` is."""
    k = ratio(record, model)
    return None if k is None else k * (flow.share if flow is not None else 1.0)


def _speeds(record: dict, model: dict, flow: FlowGain | None, k: float) -> dict:
    return {"record_speed_per_volt": float(f"{record['speed_per_volt']:.6g}"),
            "model_speed_per_volt": float(f"{model['speed_per_volt']:.6g}"),
            "model_flow_gain_share": round(flow.share if flow is not None else 1.0, 4), "ratio": round(k, 4)}


def check(spec, rec: Record, runner, n: int, start: int, base_out, joints: list[str],
          flows: dict[str, FlowGain] | None = None) -> dict:
    """The scale check on the first ``n`` samples of the calibrated baseline model ``spec`` (``flows``:
    its joints' flow gains, :func:`flow_gains`; a joint without one counts the model's as the spec's);
    for each flagged joint, the validation angle fit (points, samples ``start``..``n``) as recorded and
    with the fix replayed (:func:`replayed`). {} when no joint is flagged."""
    flows = flows or {}
    found = {}
    for j, e in evidence(rec, base_out, spec, joints, n).items():
        r, m = e["record"], e["model"]
        k = against_spec(r, m, flows.get(j))
        if too_fast(k):
            found[j] = {**_speeds(r, m, flows.get(j), k), "fit": points(replay_fit(rec, j, base_out, start, n)),
                        **replayed(spec, rec, runner, n, start, j, k, flows.get(j))}
    if not found:
        return {}
    return {"joints": found, "rule": (f"the record moves more than {SCALE_LIMIT:g} times faster per volt of command than "
                                      f"the spec's valve lets the model move (the record's speed per volt over the "
                                      f"calibrated model's, times its flow gain's share of the spec's; both with their "
                                      f"command, each correlation at least {CORRELATION_MIN:g})")}


def reversed_check(model, rec: Record, runner, n: int, start: int, signs: dict,
                   flows: dict[str, FlowGain] | None = None) -> dict:
    """Of the joints the sign check found moving against their command (``signs``: polarity.check's
    result) where neither reversal alone explains the record, those that also move more than
    SCALE_LIMIT times faster per volt than the spec's valve (the speeds' sizes, as :func:`check`
    counts them), with the fix of both replayed on the calibrated model ``model``: the command
    reversed and scaled (:func:`replayed`). {} when there is none."""
    flows = flows or {}
    found = {}
    for j, e in (signs or {}).get("joints", {}).items():
        if not e.get("reversed") or "fit" not in e or polarity_explains(e) is not None:
            continue
        r, m = e["record"], e["model"]
        k = against_spec({key: abs(v) for key, v in r.items()}, {key: abs(v) for key, v in m.items()}, flows.get(j))
        if too_fast(k):
            found[j] = {**_speeds(r, m, flows.get(j), k), "fit": e["fit"],
                        **replayed(model, rec, runner, n, start, j, k, flows.get(j), sign=-1.0)}
    if not found:
        return {}
    return {"joints": found, "rule": (f"the record moves against its command and more than {SCALE_LIMIT:g} times faster "
                                      f"per volt than the spec's valve lets the model move, and neither reversal alone "
                                      f"explains it")}


def reversed_causes(result: dict, spec) -> list[str]:
    """What :func:`reversed_check` found, one sentence per joint."""
    lines = []
    for j, e in (result or {}).get("joints", {}).items():
        unit = column_unit(f"q_{j}", spec)
        lines.append(
            f"on {j} the recorded joint moves against its command and {e['ratio']:.3g} times faster per volt than the "
            f"spec's valve lets the model move (record {e['record_speed_per_volt']:+.3g} {unit}/s per V, calibrated "
            f"model {e['model_speed_per_volt']:+.3g}): the command is logged both reversed and in another scale than "
            f"the valve saw. Validation fit {fit_text(e['fit'])} as recorded, " + _fix_text(e, j))
    return lines


def off_scale(k: float) -> bool:
    """Whether a calibrated flow gain ``k`` times the spec's is more than a datasheet's tolerance can be."""
    return k > SCALE_LIMIT or 0.0 < k < 1.0 / SCALE_LIMIT


def flow_gain(model, rec: Record, runner, n: int, start: int, base_out, flow: FlowGain) -> dict | None:
    """The check of a valve flow gain that the calibrated model ``model`` (``base_out``: its outputs)
    holds at more than SCALE_LIMIT times the spec's (or under its inverse), ``flow``: the fix replayed
    (:func:`replayed`) beside the validation angle fit (points, samples ``start``..``n``) as calibrated.
    None for a flow gain within that."""
    j = flow.key.split(".")[1]
    k = flow.share
    if j not in rec.joint_names or not off_scale(k):
        return None
    return {"joint": j, "ratio": round(k, 4), "fit": points(replay_fit(rec, j, base_out, start, n)),
            **replayed(model, rec, runner, n, start, j, k, flow)}


def explained_by_scale(e: dict) -> bool:
    """Whether the command's scale can account for a ratio (:func:`replayed`'s factor): not where the
    logged command already reaches (nearly) the end of its range, so that reading it larger leaves no
    more than a flow gain's tolerance (SCALE_LIMIT) of the ratio to take."""
    return abs(e["factor"]) >= SCALE_LIMIT or abs(e["factor"]) <= 1.0 / SCALE_LIMIT


def _fix_text(e: dict, j: str) -> str:
    """The replayed fix (:func:`replayed`'s keys) and how to read the command so; where the command's
    scale cannot account for the ratio, what to check instead."""
    f = e["factor"]
    if not explained_by_scale(e):
        return (f"{fit_text(e['fit_command_scaled'])} with the command scaled by {f:.4g} onto the end of its range. "
                f"The logged command already reaches its range's end, so it is not logged smaller than the valve saw: "
                f"check the position's unit and the sensor model (joints.{j}.sensor.A), the time column's unit (a "
                f"time in minutes read as seconds makes every joint 60 times faster) and the valve's rated flow")
    return (f"{fit_text(e['fit_command_scaled'])} with the command scaled by {f:.4g}"
            + ("" if abs(f) == e["ratio"] else " (its largest value onto the end of the command range)")
            + (f" and the flow gain at {e['flow_gain_share']:.3g} times the spec's (inside its declared range)"
               if "flow_gain_share" in e else "")
            + f". Read the command scaled (`--column u_{j}=SOURCE:*{f:.4g}`, or by the amplifier's known factor)")


def flow_gain_cause(row: dict) -> str | None:
    """What a calibration stand-in row (diagnosis.json's ``calibration.stand_ins`` item) with a
    ``command_scale`` check says to check, one sentence; None without one."""
    e = row.get("command_scale")
    if not e:
        return None
    j, k = e["joint"], e["ratio"]
    return (f"the calibrated valve on {j} passes {k:.3g} times the spec's flow per volt: the record moves that much "
            f"{'faster' if k > 1.0 else 'slower'} per volt of command than the spec's valve lets it. Check the valve's "
            f"rated flow (datasheet or type code), and the command's scale: a command logged in another scale than "
            f"the valve saw (a 0..1 fraction or a controller output before its amplifier's gain, another unit) shows "
            f"the same. Validation fit {fit_text(e['fit'])} as calibrated, " + _fix_text(e, j))


def causes(result: dict, spec) -> list[str]:
    """What to check in the record or the spec, one sentence per flagged joint."""
    lines = []
    for j, e in (result or {}).get("joints", {}).items():
        unit = column_unit(f"q_{j}", spec)
        share = e.get("model_flow_gain_share", 1.0)
        lines.append(
            f"on {j} the recorded joint moves {e['ratio']:.3g} times faster per volt of command than the spec's valve "
            f"lets the model move (record {e['record_speed_per_volt']:+.3g} {unit}/s per V, calibrated model "
            f"{e['model_speed_per_volt']:+.3g}"
            + ("" if share == 1.0 else f" with its flow gain at {share:.3g} times the spec's") + "), and no "
            f"effect makes a joint faster than its valve: the command is logged in another scale than the valve saw "
            f"(a 0..1 fraction or a controller output before its amplifier's gain, another unit), or the valve is "
            f"larger than the spec's (joints.{j}.valve.rated_flow and its [estimated] range). Validation fit "
            f"{fit_text(e['fit'])} as recorded, " + _fix_text(e, j))
    return lines
