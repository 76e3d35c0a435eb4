"""An estimated parameter the record pushes past an end of its declared range.

A rig's spec marks what its user does not know (the load, the supply) estimated, with a range. Where
the baseline calibration stops such a parameter at an end of that range, it goes back to nominal
(calibration.identifiability: a misfit that is not this parameter's to absorb, for an effect may be
pushing it there). But the range is the user's guess too: a 10 kg load on a rig declared for 20-85 kg
moves it as no effect of the bank does, and a candidate that makes up some of it (a 1 % valve
asymmetry for the load's pull) was named without a word about the load. So such a parameter is a stand-in for
every named effect (decision.stand_in), freed beyond the end it stopped at by as much as its range
is wide, and on to where what it measures is absent where its effect declares that an everyday
state (``Parameter.absent``: a load set down, far below any range declared for it), inside the
parameter's physical bounds, in the effect's place. Where it explains the
record by the threshold better than the effect (with its value outside the declared range, not
inside), the effect was standing in for it: a calibration finding, the range the one to correct.
Where as well (the load's pull and a valve asymmetry set the same up/down speeds on a record
without pressures), the record does not tell them apart: the effect stays named and says so
(``as_well_beyond_range``), with the measurement that decides.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from .calibration import at_bound, keep_rank
from .command_scale import flow_gain_cause
from .parameters import FreeParameter, declared


def stopped_at_an_end(spec, changes: list[dict], free: list[FreeParameter], nuisance: set[str]) -> list[FreeParameter]:
    """The estimated parameters (``nuisance`` keys of ``free``) whose calibration (``changes`` rows)
    stopped at an end of their declared range, each widened beyond that end (:func:`widened`, inside
    the physical bounds the model ``spec`` declares for it)."""
    by_key = {fp.key: fp for fp in free}
    out = []
    for row in changes:
        fp = by_key.get(row["parameter"])
        if fp is None or fp.key not in nuisance or row["identified"]:
            continue
        side = at_bound(fp, row["fitted"])
        if side is not None:
            p = declared(spec, fp.key)
            wide = widened(fp, side, (p.lower, p.upper), p.absent)
            if wide is not None:
                out.append(wide)
    # tried in the calibration's own order of what a rig's user least knows (calibration.KEEP_ORDER:
    # without pressures a load carries what it and the supply explain together)
    return sorted(out, key=lambda fp: keep_rank(fp.key))


@dataclass
class BeyondRange(FreeParameter):
    """An estimated parameter freed beyond its declared range (``declared``: that range). It explains
    a record beyond the range only with a value outside it: inside, what explained the record was the
    refit of the others, not the range."""

    declared: tuple[float, float] = (-math.inf, math.inf)

    def within_declared(self, value: float) -> str | None:
        """Why ``value`` is no finding beyond the range (it lies inside it), else None."""
        lo, hi = self.declared
        return f"inside its declared range [{lo:.4g}, {hi:.4g}]" if lo <= value <= hi else None


def widened(fp: FreeParameter, side: str, bound: tuple[float, float], absent: float | None = None) -> BeyondRange | None:
    """``fp`` with its ``side`` ('lower' or 'upper') end moved beyond it by as much as the range is
    wide (by its ratio, on a log scale), and on to ``absent`` (the value where what it measures is not
    there: a load set down) where that lies farther on that side, inside the physical ``bound``; None
    where there is no room."""
    lower, upper = fp.lower, fp.upper
    if side == "lower":
        lower = fp.lower * fp.lower / fp.upper if fp.log else fp.lower - (fp.upper - fp.lower)
        if absent is not None:
            lower = min(lower, absent)
        lower = max(lower, bound[0])
        if not lower < fp.lower:
            return None
    else:
        upper = fp.upper * fp.upper / fp.lower if fp.log else fp.upper + (fp.upper - fp.lower)
        if absent is not None:
            upper = max(upper, absent)
        upper = min(upper, bound[1])
        if not upper > fp.upper:
            return None
    out = BeyondRange(**{f.name: getattr(fp, f.name) for f in fields(FreeParameter)}, declared=(fp.lower, fp.upper))
    out.lower, out.upper = lower, upper
    out.range_declared = False          # widened beyond what the spec declares
    out.log = out.lower > 0 and out.upper / out.lower > 3.0
    return out


def describe(item: dict) -> list[str]:
    """A named effect's ``as_well_beyond_range`` rows (diagnosis.json's ``selected`` item) as the
    lines the output and the reports print."""
    return [f"as well explained by {r['parameter']} = {r['value']:.4g}, beyond its declared range "
            f"[{r['declared_range'][0]:.4g}, {r['declared_range'][1]:.4g}] ({r['score'] - r['score_with_effect']:+.2f} "
            f"points): the record does not tell them apart; decided by {r['decided_by']}"
            for r in item.get("as_well_beyond_range", [])]


def found(calibration: dict) -> list[str]:
    """The calibration's findings beyond a declared range (diagnosis.json's ``calibration.stand_ins``
    rows with a ``declared_range``): one line per parameter (a parameter that stood in for several
    effects names each), for the output and the reports, with what a flow gain far off the spec's says
    of the command's scale (command_scale.flow_gain_cause)."""
    rows: dict[str, list[dict]] = {}
    for r in calibration.get("stand_ins", []):
        if "declared_range" in r:
            rows.setdefault(r["parameter"], []).append(r)
    lines = []
    for key, group in rows.items():
        r = max(group, key=lambda g: g["score"] - g["score_with_effect"])
        lo, hi = r["declared_range"]
        places = ", ".join(dict.fromkeys(g["in_place_of"]["effect"] + (f" on {g['in_place_of']['joint']}"
                                                                        if g["in_place_of"].get("joint") else "")
                                         for g in group))
        unit = f" {r['unit']}" if r.get("unit") else ""
        line = (f"{key} = {r['value']:.4g}{unit} (spec {r['nominal']:.4g}), beyond its declared range "
                f"[{lo:.4g}, {hi:.4g}]: calibrated there in place of {places}, it explains the record better "
                f"(up to {r['score'] - r['score_with_effect']:+.2f} points). Correct the spec or its [estimated] range")
        cause = flow_gain_cause(r)
        lines.append(line + (f"; {cause}" if cause else ""))
    return lines
