"""Does the record move the way the model does? The sign conventions between a rig and its spec.

A spec fixes which way a positive command moves each joint (the valve's A port, the actuator's
geometry) and which way a rising sensor voltage reads (the sign of the sensor's gain ``A``). A
position sensor wired the other way, or a valve whose ports or amplifier leads are swapped against
the spec, leaves every parameter right and one sign wrong: the record's joint moves against its
command where the model's moves with it. No parameter or effect of the bank reverses that, so the
record stays unexplained; this check says why and tries the two fixes, each by a replay of the model:

* the command reversed (``u -> -u``): the valve or its amplifier wired the other way round;
* the position mirrored (``q -> c - q``: the sensor's gain reversed, ``A -> -A``, ``B -> c - B``),
  with ``c`` searched over the values that keep the mirrored record inside the joint's range (where
  the joint stands sets its gravity load and end stops). Only the fit is reported: on a vertical
  cylinder the load is the same at every stroke, and the record fixes ``c`` (so ``B``) only loosely.

Evidence per joint: which way it moves per volt of command (``closed_loop.direction``: the slope
of the smoothed velocity on the command and their correlation, where the command is inside its
range), for the record and for the baseline model driven by the same command. A hydraulic valve meters flow, so the speed follows the
command closely (correlations of 0.95 or more on the templates' closed-loop records and on the
built-in robots' open-loop ones); a reversal is flagged where the two correlations have opposite
signs and each reaches ``CORRELATION_MIN``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..dataset import column_unit
from .closed_loop import direction
from .metrics import nrmse_fit
from .record import Record

CORRELATION_MIN = 0.5     # |correlation| of command and speed each side must reach for a reversal
MIRROR_GRID = 9           # mirror points c tried across their feasible interval, then refined
MIRROR_REFINE = 8         # golden-section steps around the best grid point


def reversed_sign(record: dict, model: dict) -> bool:
    """Whether the record's joint moves against its command where the model's moves with it (or the
    other way): opposite correlations, each at least ``CORRELATION_MIN`` in size."""
    r, m = record["correlation"], model["correlation"]
    return abs(r) >= CORRELATION_MIN and abs(m) >= CORRELATION_MIN and (r > 0) != (m > 0)


def evidence(rec: Record, out, spec, joints: list[str], n: int) -> dict:
    """Per joint: the record's and the model's direction (over the first ``n`` samples) and whether
    they disagree. ``out``: the baseline model's outputs on ``rec``'s command."""
    res = {}
    for j in joints:
        if not out.ok or j not in out.angles:
            continue
        rng = spec.joint(j).command_range
        u = rec.u(j)[:n]
        r = direction(u, rec.angles[j][:n], rec.dt, rng)
        m = direction(u, out.angles[j][:n], rec.dt, rng)
        res[j] = {"record": _rounded(r), "model": _rounded(m), "reversed": reversed_sign(r, m)}
    return res


def check(spec, rec: Record, runner, n: int, start: int, base_out, joints: list[str]) -> dict:
    """The sign check on the baseline model ``spec`` and its outputs ``base_out``; for each joint
    whose direction is reversed, the validation angle fit (points, samples ``start``..``n``) as
    recorded, with the command reversed and with the position mirrored (the best mirror point).
    ``runner`` simulates the replays. {} when no joint is reversed."""
    ev = evidence(rec, base_out, spec, joints, n)
    flagged = [j for j, e in ev.items() if e["reversed"]]
    if not flagged:
        return {}
    out = {"joints": ev, "rule": (f"the record's and the model's correlation of command and speed have opposite signs, "
                                  f"each at least {CORRELATION_MIN:g} in size")}
    for j in flagged:
        fit = replay_fit(rec, j, base_out, start, n)
        flipped = runner.simulate(spec, n, rec=with_command(rec, j, -1.0))
        mirrored = _best_mirror(spec, rec, runner, j, n, start)
        ev[j].update({"fit": points(fit), "fit_command_reversed": points(replay_fit(rec, j, flipped, start, n)),
                      "fit_position_mirrored": points(mirrored)})
    return out


def causes(result: dict, spec) -> list[str]:
    """What to check in the record or the spec, one sentence per reversed joint."""
    lines = []
    for j, e in (result or {}).get("joints", {}).items():
        if not e["reversed"]:
            continue
        unit = column_unit(f"q_{j}", spec)
        said = (f"on {j} the recorded position moves against the command where the model's moves with it (record "
                f"{e['record']['speed_per_volt']:+.3g} {unit}/s per V of command, correlation "
                f"{e['record']['correlation']:+.2f}; model {e['model']['speed_per_volt']:+.3g} {unit}/s per V, "
                f"{e['model']['correlation']:+.2f}): a sign "
                f"convention of the rig differs from its spec's, which no parameter or effect reverses. Validation fit "
                f"{fit_text(e['fit'])} as recorded, {fit_text(e['fit_command_reversed'])} with the command reversed, "
                f"{fit_text(e['fit_position_mirrored'])} with the position mirrored")
        best = explains(e)
        if best == "command":
            said += (f". The command reversed explains it: the valve (or its amplifier) is wired the other way round "
                     f"from the spec; read the command reversed (`--column u_{j}=SOURCE:*-1`) or swap the valve's leads")
        elif best == "position":
            sensor = spec.joint(j).components.get("sensor")
            fix = ""
            if sensor is not None:
                fix = (f" (joints.{j}.sensor.A = {-float(sensor['A']):.6g}, and its [estimated] range) and read its "
                       f"offset B again at a known position (moving B's range with it), then import the volts again")
            said += (f". The position mirrored explains it: the position sensor reads the other way round from "
                     f"the spec; reverse the sign of its gain{fix}")
        else:
            said += (". Neither reversal alone explains it: check the command's and the sensor's wiring against "
                     "the spec (which way a positive command moves the joint, which way the reading rises)")
        lines.append(said)
    return lines


EXPLAINS_MARGIN = 20.0    # points a fix must gain over the record as is, and over the other fix


def explains(e: dict) -> str | None:
    """The reversal that explains the record: at least ``EXPLAINS_MARGIN`` points above the fit as
    recorded and above the other reversal, and a positive fit."""
    base = _val(e["fit"])
    cmd, pos = _val(e["fit_command_reversed"]), _val(e["fit_position_mirrored"])
    for name, f, other in (("command", cmd, pos), ("position", pos, cmd)):
        if f > 0.0 and f >= base + EXPLAINS_MARGIN and f >= other + EXPLAINS_MARGIN:
            return name
    return None


def _best_mirror(spec, rec: Record, runner, j: str, n: int, start: int) -> float:
    """The best fit (points) of the model to the record mirrored, ``c - q``, over the mirror point ``c``
    (position units; where the joint stands may fix it only loosely, so it is not reported). ``c``
    keeps the mirrored record inside the joint's range; a joint without limits is searched one
    recorded span either side of mirroring in place."""
    q = rec.angles[j][:n]
    q = q[np.isfinite(q)]
    if q.size == 0:
        return -math.inf
    qmin, qmax = float(q.min()), float(q.max())
    i = spec.tree.index(spec.joint(j).dof)
    lower, upper = float(spec.tree.lower[i]), float(spec.tree.upper[i])
    span = max(qmax - qmin, 1e-6)
    lo = lower + qmax if math.isfinite(lower) else qmin + qmax - span
    hi = upper + qmin if math.isfinite(upper) else qmin + qmax + span
    if lo > hi:                       # the record spans more than the range: mirror in place
        lo = hi = qmin + qmax
    seen: dict[float, float] = {}

    def fit_at(c: float) -> float:
        if c not in seen:
            angles = dict(rec.angles)
            angles[j] = c - rec.angles[j]
            pose = dict(rec.initial_pose)
            pose[j] = c - pose[j]
            mirrored = replace(rec, angles=angles, initial_pose=pose)
            seen[c] = replay_fit(mirrored, j, runner.simulate(spec, n, rec=mirrored), start, n)
        return seen[c]

    grid = np.linspace(lo, hi, MIRROR_GRID) if hi > lo else np.array([lo])
    fits = [fit_at(float(c)) for c in grid]
    k = int(np.argmax(fits))
    if grid.size > 1:
        a, b = float(grid[max(k - 1, 0)]), float(grid[min(k + 1, grid.size - 1)])
        g = (math.sqrt(5.0) - 1.0) / 2.0
        x1, x2 = b - g * (b - a), a + g * (b - a)
        for _ in range(MIRROR_REFINE):
            if fit_at(x1) >= fit_at(x2):
                b, x2 = x2, x1
                x1 = b - g * (b - a)
            else:
                a, x1 = x1, x2
                x2 = a + g * (b - a)
    return max(seen.values())


def with_command(rec: Record, j: str, scale: float = 1.0, shift: float = 0.0) -> Record:
    """``rec`` with joint ``j``'s command read as ``scale * u + shift`` (V): the record a fix replays."""
    U = rec.U.copy()
    k = rec.joint_names.index(j)
    U[:, k] *= scale
    if shift:
        U[:, k] += shift
    return replace(rec, U=U)


def replay_fit(rec: Record, j: str, out, start: int, n: int) -> float:
    """The angle fit (points) of joint ``j`` on samples ``start``..``n`` of a replay ``out``; -inf if it failed."""
    if not out.ok or j not in out.angles:
        return -math.inf
    return float(nrmse_fit(rec.angles[j][start:n], out.angles[j][start:n]))


def _val(v) -> float:
    return -math.inf if v is None else float(v)


def points(v: float):
    return None if not math.isfinite(v) else round(float(v), 2)


def fit_text(v) -> str:
    return "none (the replay diverged)" if v is None else f"{v:.1f} %"


def _rounded(d: dict) -> dict:
    return {"speed_per_volt": float(f"{d['speed_per_volt']:.6g}"), "correlation": round(d["correlation"], 4)}
