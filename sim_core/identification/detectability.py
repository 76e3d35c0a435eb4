"""What a record can show: for every effect of the bank the diagnosis did not name, the smallest
magnitude that would have reached the acceptance threshold on this record (and for each one it
named, the same on the model without it: how far above that the named value is).

"No significant discrepancy" is only as strong as the record behind it. A Coulomb friction on a
position-only record sets the same speeds per volt as the valve's flow gain; a sensor offset moves
the model's start pose with it, since the start is read off the same sensor; a flow limit the
excitation never reaches leaves no trace. So each effect is put into the final model at a ladder of
magnitudes (shares of the way, in its fit coordinate, from where it vanishes to the far end of its
search range), simulated, and the model's calibrated parameters are refitted to that output to first
order: least squares on the final fit's own Jacobian columns. What the refit cannot take up, with the
record's noise drawn on top, is the gain a candidate of that magnitude could show; the smallest rung
whose gain reaches the threshold is what the record shows, none: the record cannot test for the
effect within the bank's range. An effect with no value where it vanishes (line dynamics replaces
the hoses' lumping at any stiffness) is tried at both ends of its range first, and its ladder runs
from the end where it shows less towards the other. An estimate (first order in the calibrated parameters, one noise
draw, the first half of the estimation window, where the fits rank their starts, and the whole
window for a ladder that shows nothing on that half; rungs a factor 2 apart, or 1/16 of a
log-scaled range), reported as one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .output_error import Problem, _simulate_all
from .simulation import Outputs

# shares of the way from the null to the far search bound, in the fit coordinate: a factor 2 apart
# for a parameter searched on a linear scale, 1/16 of the range apart on a log scale (a factor 2
# there would span decades near the null)
LINEAR_SHARES = tuple(2.0 ** -k for k in range(7, -1, -1))
LOG_SHARES = tuple(k / 16 for k in range(1, 17))
SEED = 20261202                               # the noise drawn on each rung's output (a fixed draw: reproducible)


def rungs(fp, toward: float | None = None) -> list[float]:
    """The ladder's values of ``fp`` (a candidate's first free parameter), nearest the null first:
    from its null towards the search bound farther from it in the fit coordinate, or, with
    ``toward`` (a named effect's value), towards the bound on that value's side (a deadband named
    narrower than the spec's 1.2 V runs down from 1.2, not up to the range's 4.5). [] where the
    parameter has no null."""
    if not has_null(fp):
        return []
    xn = fp.to_x(fp.null)
    xt = math.nan if toward is None else fp.to_x(toward)
    xf = (0.0 if xt < xn else 1.0) if math.isfinite(xt) and xt != xn else (1.0 if 1.0 - xn >= xn else 0.0)
    return [fp.from_x(xn + s * (xf - xn)) for s in (LOG_SHARES if fp.log else LINEAR_SHARES)]


def one_way(fp, toward: float) -> list[float]:
    """A ladder over ``fp``'s whole range in sixteenths of its fit coordinate, from the bound that is
    not ``toward`` to ``toward`` (that bound excluded, ``toward`` last): for a parameter with no null."""
    xf = fp.to_x(toward)
    xn = 1.0 - xf
    return [fp.from_x(xn + s * (xf - xn)) for s in LOG_SHARES]


def has_null(fp) -> bool:
    """Whether ``fp`` has a value where its effect vanishes (infinity counts: a flow limit's)."""
    return fp.null is not None and not math.isnan(fp.null)


def rows_within(full: Problem, part: Problem) -> np.ndarray:
    """The rows of ``full``'s residual (and Jacobian) that ``part`` has: both start at the same sample
    and ``part`` ends earlier (a shorter window of the same channels)."""
    idx, pos = [], 0
    for k, y in full.meas.items():
        if k in part.meas:
            idx.append(pos + np.arange(part.meas[k].size))
        pos += y.size
    return np.concatenate(idx) if idx else np.zeros(0, dtype=int)


def absorbed(problem: Problem, base: Outputs, truth: Outputs, jacobian: np.ndarray | None) -> Outputs:
    """``base``'s outputs with the calibrated parameters refitted, to first order, to ``truth``: the
    least-squares step on ``jacobian`` (d residual / d x over the problem's channels) that brings the
    model closest to ``truth``, applied to the simulated angles and pressures (the velocity channel
    follows from the angle; its rows take part in the step)."""
    angles = {j: np.array(a, dtype=float) for j, a in base.angles.items()}
    pressures = {j: [np.array(pa, dtype=float), np.array(pb, dtype=float)] for j, (pa, pb) in base.pressures.items()}
    if jacobian is not None and jacobian.size and np.all(np.isfinite(jacobian)):
        d = problem.residuals(base) - problem.residuals(truth)      # the model's residual against truth
        step, *_ = np.linalg.lstsq(jacobian, -d, rcond=None)
        change = -(jacobian @ step)                                 # of the simulated channels, residual units
        sl = slice(problem.start, problem.n)
        pos = 0
        for (j, ch), y in problem.meas.items():
            seg = change[pos: pos + y.size] * problem.scale[(j, ch)] / math.sqrt(problem.weight[(j, ch)])
            pos += y.size
            if ch == "angle":
                angles[j][sl] += seg
            elif ch in ("p_a", "p_b"):
                pressures[j][0 if ch == "p_a" else 1][sl] += seg
    return Outputs(angles, {j: (pa, pb) for j, (pa, pb) in pressures.items()})


def expected_gain(problem: Problem, base: Outputs, truth: Outputs, jacobian: np.ndarray | None, joints: list[str],
                  noise: dict[str, float], pressure_noise: dict[str, float], restart: int) -> float:
    """The score gain (points) a candidate that reproduces ``truth`` shows over the baseline refitted to it,
    on a record of ``truth`` with the record's noise (angle ``noise`` in rad, ``pressure_noise`` in Pa)."""
    if not (truth.ok and base.ok):
        return math.nan
    rec = problem.redrawn(truth, noise, pressure_noise, np.random.default_rng(SEED))
    if restart:
        rec = rec.restarting(restart)
    with_effect = rec.fits(truth)
    without = rec.fits(absorbed(problem, base, truth, jacobian))
    return float(np.mean([with_effect[j]["score"] - without[j]["score"] for j in joints]))


def shown(groups: list[tuple], runner, problem: Problem, joints_of, *, threshold: float, noise: dict[str, float],
          pressure_noise: dict[str, float], restart: int = 0, side=None,
          whole: tuple[Problem, list] | None = None) -> list[dict]:
    """For each candidate of each group ``(model, jacobian, cands, named)`` or ``(model, jacobian,
    cands, named, values)`` (effects not in ``model``; ``jacobian`` its calibrated parameters' columns,
    None: nothing calibrated; ``values``: (effect, joint) -> a named effect's first parameter, whose
    side of the null its ladder runs to): its first parameter's
    ladder searched by bisection for the smallest rung whose expected gain reaches ``threshold``, the
    top rung first (none there: not testable within the range). ``joints_of(cand)``: the joints its
    gain is scored on; ``named`` marks the rows of the effects the diagnosis named (searched on the
    model without them: how far above what the record shows they are). The candidates' searches run
    side by side, each whole in one process (a search's next rung waits only for its own last).
    ``whole``: (a longer window, each group's Jacobian over it) where a ladder that shows nothing
    within its range on ``problem`` is searched again: a short window can hold one direction of a
    joint's motion only (a closed-loop boom that rises for its first seconds shows no valve
    asymmetry there, however large); each row's ``window`` says which one it was found on."""
    bases = _simulate_all(runner, [g[0].copy() for g in groups], problem.n, side)
    todo = []
    search = _Search(groups, bases, runner, problem, joints_of, threshold, noise, pressure_noise, restart, todo)
    weaker: dict[int, tuple] = {}          # todo index -> (the bound a no-null ladder starts from, its gain)
    for gi, group in enumerate(groups):
        cands, named_values = group[2], (group[4] if len(group) > 4 else {})
        for c in cands:
            if not c.free:
                continue
            fp = c.free[0]
            if has_null(fp):
                values = rungs(fp, named_values.get((c.effect, c.joint)))
            else:
                # no value where it vanishes: towards the end of the range where it shows more
                at = {b: search.gain(gi, c, b) for b in (fp.lower, fp.upper)}
                g = {b: v if math.isfinite(v) else -math.inf for b, v in at.items()}
                toward = fp.upper if g[fp.upper] > g[fp.lower] else fp.lower
                start = fp.lower if toward == fp.upper else fp.upper
                weaker[len(todo)] = (start, at[start])
                values = one_way(fp, toward)
            if values:
                todo.append((gi, c, values))
    found = _searched(search, side)
    window = ["first"] * len(todo)
    again = [i for i, (hi, _) in enumerate(found) if hi is None]
    if whole is not None and again:
        longer, jacobians = whole
        wgroups = [(g[0], jacobians[gi]) + tuple(g[2:]) for gi, g in enumerate(groups)]
        wbases = _simulate_all(runner, [g[0].copy() for g in groups], longer.n, side)
        wsearch = _Search(wgroups, wbases, runner, longer, joints_of, threshold, noise, pressure_noise, restart,
                          [todo[i] for i in again])
        for i, f in zip(again, _searched(wsearch, side)):
            found[i], window[i] = f, "whole"
    out = []
    for i, ((gi, c, values), (hi, gains)) in enumerate(zip(todo, found)):
        fp = c.free[0]
        name = fp.key.split(".")[-1]
        first = [{"value": _num(weaker[i][0]), "expected_gain": _num(weaker[i][1])}] if i in weaker else []
        out.append(({"from_weaker_end": first[0]["value"]} if first else {}) | {
            "effect": c.effect, "joint": c.joint, "parameter": name, "unit": fp.unit, "null": _num(fp.null),
            "named": bool(groups[gi][3]), "range_end": _num(values[-1]),
            "shows_from": None if hi is None else _num(values[hi]),
            "tested": first + [{"value": _num(values[k]), "expected_gain": _num(g)} for k, g in sorted(gains.items())],
            "window": WINDOWS[window[i]],
        })
    return out


WINDOWS = {"first": "the first half of the estimation window", "whole": "the estimation window"}


def _searched(search: "_Search", side) -> list[tuple[int | None, dict[int, float]]]:
    """Every ladder of ``search`` bisected (side by side where ``side`` is given)."""
    indices = list(range(len(search.todo)))
    return side.map(_bisect, indices, hold=search) if side is not None else [search.bisect(i) for i in indices]


@dataclass
class _Search:
    """What every candidate's bisection reads (held by the processes that run them side by side)."""

    groups: list[tuple]
    bases: list[Outputs]
    runner: object
    problem: Problem
    joints_of: object
    threshold: float
    noise: dict[str, float]
    pressure_noise: dict[str, float]
    restart: int
    todo: list[tuple]          # (group index, candidate, ladder values)

    def gain(self, gi: int, cand, value: float) -> float:
        """The expected gain of ``cand`` at ``value`` over group ``gi``'s model (nan: the model refuses
        the value, or diverges there)."""
        model, jacobian = self.groups[gi][0], self.groups[gi][1]
        try:
            s = cand.prepare(model)
            cand.free[0].apply(s, value)
        except ValueError:          # a value the model refuses: that rung fails, as a diverged one does
            return math.nan
        out = self.runner.simulate(s, self.problem.n, owned=True)
        return expected_gain(self.problem, self.bases[gi], out, jacobian, self.joints_of(cand), self.noise,
                             self.pressure_noise, self.restart)

    def bisect(self, i: int) -> tuple[int | None, dict[int, float]]:
        """Candidate ``i``'s ladder: (index of the smallest rung that reaches the threshold, None: not
        even the top one; the expected gain of every rung tried)."""
        gi, cand, values = self.todo[i]
        gains: dict[int, float] = {}
        lo, hi, k = -1, len(values) - 1, len(values) - 1
        while k is not None:
            g = self.gain(gi, cand, values[k])
            gains[k] = g
            passes = math.isfinite(g) and g >= self.threshold
            if k == len(values) - 1 and not passes:
                hi = None                           # not even at the far end of the range
            elif passes:
                hi = k
            else:
                lo = k
            k = None if hi is None or hi - lo <= 1 else (lo + hi) // 2
        return hi, gains


def _bisect(i: int):
    from .side_by_side import held

    return held().bisect(i)


def magnitude(row: dict, value: float) -> str:
    """``value`` of ``detectable``'s row's parameter, with its unit: 'width = 0.2812 V'."""
    return f"{row['parameter']} = {value:.4g}" + (f" {row['unit']}" if row["unit"] else "")


def describe(row: dict, threshold: float) -> str:
    """One line of the CLI's answer for ``detectable``'s row."""
    where = f" on {row['joint']}" if row["joint"] else ""
    if row["shows_from"] is None:
        top = row["tested"][-1]["expected_gain"] if row["tested"] else None
        gain = f", {top:+.2f} points there" if top is not None else ""
        return (f"{row['effect']}{where}: not even at {magnitude(row, row['range_end'])} (the far end of "
                f"its range{gain}, under the {threshold:g} a gain must reach)")
    return f"{row['effect']}{where}: from about {magnitude(row, row['shows_from'])}{from_spec(row)}"


def from_spec(row: dict) -> str:
    """Where the ladder of ``row`` starts, said where that is not zero (a spec's own deadband, a valve's
    ratio of 1): ', none at width = 1.2 V'. A magnitude is read from there."""
    null = row.get("null")
    if null is None or null == 0.0 or not math.isfinite(null):
        return ""
    return f", none at {magnitude(row, null)}"


def _num(v):
    v = float(v)
    return v if math.isfinite(v) else None
