"""Which calibrated parameters the record cannot identify go back to nominal, and in what order.

After the first fit of every freed parameter:

* while none of those still free is identified, only the weakest goes (pushed to an end of its
  range first, then one tied to another by a correlation, then the lowest ``|value/sigma|``) and
  the rest are refitted and judged again: a misfit that an effect the model lacks dominates (a wide
  deadband) can leave every parameter unidentified at first;
* once some are identified, every one that is not goes at once, and after that only a parameter
  that a refit pushes to an end of its range;
* a baseline parameter (``last``: the valve flow gains) goes only when nothing else is left to go,
  or at an end of its range: without pressures a closed-loop record fixes how fast the joint moves
  per volt, not whether the valve, the supply or the sensor's gain makes it so, and with the flow
  gain reset with the others the model was left at its nominal speed (a hanging cylinder whose valve
  is 60 % larger than its spec: its deadband unexplained).

Not one at a time to the end: in a closed-loop record without pressures a parameter below
``|value/sigma| = 3`` beside identified ones is typically half of a pair the record barely tells
apart (a flow gain and a supply pressure or a sensor gain); kept, it is then identified and carries
what the two explain together, and the effects named afterwards inherit its error (measured on a
hanging cylinder's 4 % leak, seeds 1-2: 22-23 % low with one-at-a-time elimination, 9 % low with
this rule before the flow gain went last, 2-3 % since; docs/rig-diagnosis-rules.md).

Unless they matter together: parameters each under ``|value/sigma| = 3`` can still be what the
record needs jointly (a supply pressure and a load mass of a cylinder without pressures: each
trades against the other, their ratio sets the load pressure). Reset together, the cost rises by
more than the 3-sigma level of a chi-square with as many degrees of freedom (in the fit's own
``cost_scale``: ``s^2 N/N_eff``; calibration's ``jointly_identified``), and every effect tried afterwards would "explain" the model that
reset broke (measured on a cylinder lifting a load along a sine: the cost 28x higher, seven
candidates within 1.2 points of each other, a deadband named as an area ratio). Then only the weakest goes and
the rest are judged again, so one of them carries what they explained together (its row says on
which held ones it is conditional).

Unless the kept partner cannot stand in: of two parameters the record cannot tell apart (a supply
pressure and a load, correlated beyond 0.98) the one ranked later goes and its partner carries what
they explained together, but where that partner is then pushed to an end of its range and the cost
rises beyond the same chi-square level, the ratio they fix lies beyond what it can carry alone (a
boom's tip load twice its spec's with the supply 13 % low: alone the load needed 89 kg of a range
ending at 85, it went too, and a 2 % valve asymmetry was named on a clean log). The partner then
stays, both keep their fitted values, and their rows say they are fixed together, not each.
``identifiability`` (calibration) says why a parameter is not identified and ``jointly_identified``
(calibration) whether several are together; this module only decides which of them go, and when.
"""

from __future__ import annotations

import math
from typing import Callable

from . import output_error as oe
from .parameters import FreeParameter


def strength(res: oe.FitResult, key: str, reason: str, rank: Callable[[str], int]) -> tuple[int, float]:
    """How well ``res`` pins ``key`` down (lowest goes first): a parameter at an end of its range is
    weakest, then one flagged for its correlation with another (of those, the one ranked later by
    ``rank``), then by its own ``|value/sigma|``."""
    if reason.startswith("at the"):
        return (-1, 0.0)
    if reason.startswith("correlation"):
        return (0, -float(rank(key)))
    v, s = res.values.get(key, 0.0), res.sigma.get(key, math.inf)
    return (1, abs(v) / s if s > 0 and math.isfinite(s) else 0.0)


def eliminate(free: list[FreeParameter], first: oe.FitResult,
              judge: Callable[[oe.FitResult], dict[str, str | None]],
              refit: Callable[[list[FreeParameter], oe.FitResult], oe.FitResult],
              rank: Callable[[str], int], last: Callable[[str], bool] = lambda key: False,
              together: Callable[[oe.FitResult, oe.FitResult, int], bool] | None = None,
              protected: dict[str, str] | None = None
              ) -> tuple[list[FreeParameter], oe.FitResult, dict[str, tuple[str, oe.FitResult]]]:
    """Drop the parameters of ``free`` the record cannot identify (module docstring) and refit the
    rest after each drop.

    ``judge(result)``: per key, None when identified, else why not (a reason starting "at the" for
    one at an end of its range). ``refit(keep, current)``: the fit of ``keep`` with the dropped
    parameters at nominal, started from ``current``'s values. Returns the kept parameters, the last
    fit (the one the last parameter was dropped on when none is kept) and, per dropped key, why and
    the fit it was judged on. ``last(key)``: a baseline parameter (module docstring).
    ``together(fit, refit without k of its parameters, k)``: whether those k, each failing only by
    |value/sigma|, are identified jointly (module docstring); None: never. ``protected``: filled with
    the keys kept although judged unidentified, and why (a correlated partner the record needs), and
    the kept parameters they were needed beside."""
    keep, current = list(free), first
    dropped: dict[str, tuple[str, oe.FitResult]] = {}
    protected = {} if protected is None else protected
    stay: set[str] = set()      # correlated partners the record needs beside a kept parameter
    bound_only = False          # after a drop beside identified parameters only one pushed to an end goes
    while keep:
        verdict = judge(current)
        failing = [fp for fp in keep if verdict.get(fp.key) is not None and fp.key not in stay
                   and (not bound_only or verdict[fp.key].startswith("at the"))]
        if not failing:
            break
        every = not bound_only and len(failing) == len(keep)
        if not bound_only and any(not last(fp.key) for fp in keep):
            # the baseline parameters go only when nothing else is left (or at a range end)
            failing = [fp for fp in failing if not last(fp.key) or verdict[fp.key].startswith("at the")]
            if not failing:
                break
        if every:
            failing = [min(failing, key=lambda fp: strength(current, fp.key, verdict[fp.key], rank))]
        # those that fail only by |value/sigma| (not at a range end, not tied to a kept partner)
        weak = [fp for fp in failing if verdict[fp.key].startswith("|value/sigma|")]
        one_by_one, trial = False, None
        if together is not None and not every and len(weak) > 1:
            others = [fp for fp in failing if fp not in weak]
            before = refit([fp for fp in keep if fp not in others], current) if others else current
            trial = refit([fp for fp in keep if fp not in failing], current)
            if together(before, trial, len(weak)):
                # one at a time while they matter together: the weakest of them goes now
                one_by_one, trial = True, None
                failing = others + [min(weak, key=lambda fp: strength(current, fp.key, verdict[fp.key], rank))]
        for fp in failing:
            dropped[fp.key] = (verdict[fp.key], current)
        keep = [fp for fp in keep if fp not in failing]
        before = current
        if keep:
            current = trial if trial is not None else refit(keep, current)
            needed = partners_needed(before, current, verdict, judge, failing, keep, together)
            if needed:
                # reset to nominal, a correlated partner pushed a kept parameter to an end of its range
                # at a cost the record rejects: the two are fixed together, each within its range
                # only beside the other, so the partner stays (flagged) and the rest is refitted
                pushed, partners = needed
                names = ", ".join(p.key for p in pushed)
                for fp in partners:
                    del dropped[fp.key]
                    stay.add(fp.key)
                    protected[fp.key] = (f"kept although {verdict[fp.key]}: reset to nominal it pushes {names} to an "
                                         "end of the range; the record fixes them together, not each")
                for fp in pushed:
                    protected.setdefault(fp.key, f"fixed together with {', '.join(p.key for p in partners)}, not "
                                                 "by itself (see its row)")
                keep = [fp for fp in free if fp in keep or fp in partners]
                current = refit(keep, before)
        if not every and not one_by_one:
            bound_only = True
    return keep, current, dropped


def partners_needed(before: oe.FitResult, after: oe.FitResult, verdict: dict[str, str | None],
                    judge: Callable[[oe.FitResult], dict[str, str | None]], gone: list[FreeParameter],
                    keep: list[FreeParameter], together) -> tuple[list[FreeParameter], list[FreeParameter]] | None:
    """(kept parameters pushed to an end of their range, the correlated partners whose reset pushed
    them) when dropping ``gone`` did that and raised the cost beyond what ``together`` allows for as
    many parameters; else None. A supply pressure and a load that the record cannot tell apart are
    still both needed where their ratio lies beyond what either can carry alone: a boom's tip load
    twice its spec's and the supply 13 % low, the load alone asked for 89 kg of a range ending at 85."""
    if together is None or not after.ok:
        return None
    now = judge(after)
    pushed = [fp for fp in keep if (now.get(fp.key) or "").startswith("at the")
              and not (verdict.get(fp.key) or "").startswith("at the")]
    # only a partner of a pushed one: the one its correlation was with (a sensor offset tied to the
    # sensor's gain does not stand in for a load that something else pushed)
    tied = {fp.key: correlated_with(verdict.get(fp.key)) for fp in gone}
    partners = [fp for fp in gone if tied[fp.key] in {p.key for p in pushed}]
    if not partners or not together(before, after, len(partners)):
        return None
    return [p for p in pushed if p.key in {tied[fp.key] for fp in partners}], partners


def correlated_with(reason: str | None) -> str | None:
    """The key a 'correlation ... with KEY: ...' reason of the calibration's ``identifiability`` names."""
    if not reason or not reason.startswith("correlation"):
        return None
    head = reason.split(": ", 1)[0]
    return head.rsplit(" with ", 1)[1] if " with " in head else None
