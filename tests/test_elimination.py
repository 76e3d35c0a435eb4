"""Which calibrated parameters go back to nominal (identification/elimination.py): on linear least
squares with known columns and on scripted fit results, no simulation; judged by the calibration's
own identifiability."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_core.identification import output_error as oe
from sim_core.identification.calibration import identifiability, jointly_identified, keep_rank
from sim_core.identification.elimination import eliminate, strength
from sim_core.identification.parameters import FreeParameter

FLOW, GAIN = "joints.lift.valve.rated_flow", "effects.sensor_gain.lift.gain"
OFFSET, MASS = "effects.sensor_offset.lift.offset", "effects.payload.lift.mass"
KEYS = [FLOW, GAIN, OFFSET, MASS]


class LinearRecord:
    """y = J theta + noise, the parameters held at 0 (their nominal value) when not free: a fit is
    ordinary least squares with the covariance s^2 (J'J)^-1, as the calibration's fits report it."""

    def __init__(self, seed: int = 3, n: int = 200, noise: float = 1.7, theta=(1.0, 1.0, 0.0, 3.0)):
        rng = np.random.default_rng(seed)
        s = rng.standard_normal((n, 4))
        # the flow and the sensor gain's columns correlate at 0.97 (below the 0.98 of the
        # correlation rule): each alone is well determined, the two together barely
        self.J = np.column_stack([s[:, 0], s[:, 0] + 0.25 * s[:, 1], s[:, 2], s[:, 3]])
        self.y = self.J @ np.array(theta) + noise * rng.standard_normal(n)
        self.free = {k: FreeParameter(k, -1e3, 1e3) for k in KEYS}
        self.fits = 0

    def fit(self, keys: list[str]) -> oe.FitResult:
        self.fits += 1
        idx = [KEYS.index(k) for k in keys]
        A = self.J[:, idx]
        theta, *_ = np.linalg.lstsq(A, self.y, rcond=None)
        r = self.y - A @ theta
        s2 = float(r @ r) / (len(r) - len(idx))
        cov = s2 * np.linalg.inv(A.T @ A)
        sd = np.sqrt(np.diag(cov))
        return oe.FitResult([self.free[k] for k in keys], dict(zip(keys, map(float, theta))), float(r @ r),
                            sigma=dict(zip(keys, map(float, sd))), correlation=cov / np.outer(sd, sd),
                            cost_scale=s2)

    def refit(self, keep: list[FreeParameter], current: oe.FitResult) -> oe.FitResult:
        return self.fit([fp.key for fp in keep])


def test_beside_identified_parameters_every_unidentified_one_goes_at_once():
    """A flow gain and a sensor gain the record barely tells apart (each |value/sigma| under 3) beside
    an identified load, neither of them needed (both at nominal in the truth): both go back to
    nominal in one step, with the offset (no effect at all), and the load is refitted alone, not one
    parameter after the other."""
    rec = LinearRecord(noise=6.0, theta=(0.0, 0.0, 0.0, 3.0))
    first = rec.fit(KEYS)
    verdict = identifiability(first)
    # the premise: the flow and the sensor gain are each unidentified with both free, the offset
    # too; the load is identified; and either of the pair alone would be identified
    assert verdict[FLOW] is not None and verdict[GAIN] is not None and verdict[OFFSET] is not None
    assert "sigma" in verdict[FLOW] and "sigma" in verdict[GAIN]
    assert verdict[MASS] is None
    assert not jointly_identified(first, rec.fit([MASS]), 3)
    rec.fits = 0
    keep, final, dropped = eliminate(list(rec.free.values()), first, identifiability, rec.refit, keep_rank,
                                    together=jointly_identified)
    assert [fp.key for fp in keep] == [MASS]
    assert set(dropped) == {FLOW, GAIN, OFFSET} and all(dropped[k][1] is first for k in dropped)
    assert rec.fits == 1
    assert identifiability(final)[MASS] is None


def test_parameters_the_record_needs_together_go_one_at_a_time():
    """The same pair, now both off nominal in the truth (each still under 3 sigma beside the other):
    reset together the cost rises far beyond the 3-sigma level of a chi-square with as many degrees
    of freedom, so only the weakest goes at a time; the one kept carries what the pair explained
    (flow + gain = 2 here) and is identified. Reset together (the rule deleted), the load alone is
    kept and the model misses what the pair explained."""
    rec = LinearRecord()
    first = rec.fit(KEYS)
    verdict = identifiability(first)
    assert verdict[FLOW] is not None and verdict[GAIN] is not None and verdict[MASS] is None   # the premise
    reset_together = rec.fit([MASS])
    assert jointly_identified(first, reset_together, 3)
    keep, final, dropped = eliminate(list(rec.free.values()), first, identifiability, rec.refit, keep_rank,
                                    together=jointly_identified)
    kept = [fp.key for fp in keep]
    assert MASS in kept and OFFSET not in kept and len(set(kept) & {FLOW, GAIN}) == 1, kept
    pair = next(k for k in kept if k != MASS)
    assert identifiability(final)[pair] is None
    assert final.values[pair] == pytest.approx(2.0, abs=3 * final.sigma[pair])
    # the final fit is as good as the record allows; the reset pair's is not
    assert final.cost - first.cost < 9.0 * first.cost_scale < reset_together.cost - first.cost
    # without the joint rule the pair goes with the offset at once and the load is kept alone
    keep, _, _ = eliminate(list(rec.free.values()), first, identifiability, rec.refit, keep_rank)
    assert [fp.key for fp in keep] == [MASS]
    # where the fit's cost scale is unknown, the joint rule says nothing (nothing is kept for it)
    assert not jointly_identified(oe.FitResult(first.free, first.values, first.cost), reset_together, 3)


def test_nothing_identified_drops_everything_and_returns_the_last_fit():
    rec = LinearRecord(noise=200.0)         # noise swamps every column
    first = rec.fit(KEYS)
    keep, final, dropped = eliminate(list(rec.free.values()), first, identifiability, rec.refit, keep_rank)
    assert keep == [] and set(dropped) == set(KEYS)
    assert rec.fits == len(KEYS)             # the first fit, then one refit per drop but the last
    assert final is dropped[list(dropped)[-1]][1]


def test_identified_parameters_are_not_refitted():
    rec = LinearRecord(noise=0.01)
    first = rec.fit([FLOW, MASS])
    rec.fits = 0
    keep, final, dropped = eliminate([rec.free[FLOW], rec.free[MASS]], first, identifiability, rec.refit, keep_rank)
    assert [fp.key for fp in keep] == [FLOW, MASS] and final is first and dropped == {} and rec.fits == 0


def _scripted(free: list[FreeParameter], values: dict[str, float], sigma: dict[str, float]) -> oe.FitResult:
    return oe.FitResult(free, values, 1.0, sigma=sigma)


def test_while_none_is_identified_only_the_weakest_goes_then_after_a_drop_only_range_ends():
    """Synthetic fits in sequence (no simulation): every parameter fails, so only the weakest (one at
    an end of its range) goes; in the refit two are identified and one is not, which goes; in the
    next refit one identified before is now just under 3 sigma (kept: after a drop beside identified
    ones only a parameter pushed to an end of its range goes) and another sits on its range's end
    (goes)."""
    mass, ps = FreeParameter(MASS, 50.0, 200.0), FreeParameter("supply.pressure", 1e7, 2e7)
    flow, gain = FreeParameter(FLOW, 1e-5, 1e-3), FreeParameter(GAIN, 0.5, 2.0)
    free = [mass, ps, flow, gain]
    first = _scripted(free, {MASS: 100.0, "supply.pressure": 2e7, FLOW: 2e-4, GAIN: 1.0},
                      {MASS: 50.0, "supply.pressure": 1e5, FLOW: 1e-4, GAIN: 1.0})
    second = _scripted([mass, flow, gain], {MASS: 100.0, FLOW: 2e-4, GAIN: 1.0}, {MASS: 5.0, FLOW: 1e-5, GAIN: 1.0})
    third = _scripted([mass, flow], {MASS: 50.0, FLOW: 2e-4}, {MASS: 1.0, FLOW: 2e-4 / 2.9})
    fourth = _scripted([flow], {FLOW: 2e-4}, {FLOW: 2e-4 / 2.9})
    script = [second, third, fourth]
    asked = []

    def refit(keep, current):
        asked.append([fp.key for fp in keep])
        return script.pop(0)

    keep, final, dropped = eliminate(free, first, identifiability, refit, keep_rank)
    assert list(dropped) == ["supply.pressure", GAIN, MASS]
    assert "at the upper end" in dropped["supply.pressure"][0] and dropped["supply.pressure"][1] is first
    assert "sigma" in dropped[GAIN][0] and dropped[GAIN][1] is second
    assert "at the lower end" in dropped[MASS][0] and dropped[MASS][1] is third
    assert asked == [[MASS, FLOW, GAIN], [MASS, FLOW], [FLOW]]
    assert [fp.key for fp in keep] == [FLOW] and final is fourth       # under 3 sigma, kept


def test_the_weakest_goes_first_range_end_then_correlation_then_value_over_sigma():
    free = [FreeParameter(MASS, 50.0, 200.0), FreeParameter(FLOW, 1e-5, 1e-3), FreeParameter(GAIN, 0.5, 2.0)]
    res = oe.FitResult(free, {MASS: 50.0, FLOW: 2e-4, GAIN: 1.0}, 0.0,
                       sigma={MASS: 0.1, FLOW: 1e-4, GAIN: 1.0})
    at_end = "at the lower end of its range [50, 200]: ..."
    tied = f"correlation +0.990 with {FLOW}: the record cannot tell them apart"
    ranked = sorted([(MASS, at_end), (GAIN, tied), (FLOW, "|value/sigma| = 2 < 3")],
                    key=lambda kr: strength(res, kr[0], kr[1], keep_rank))
    assert [k for k, _ in ranked] == [MASS, GAIN, FLOW]
    # among those judged by |value/sigma| the lower ratio goes first
    assert strength(res, GAIN, "|value/sigma| = 1 < 3", keep_rank) < strength(res, FLOW, "|value/sigma| = 2 < 3",
                                                                               keep_rank)
    # of two flagged for correlation the one ranked later in KEEP_ORDER goes first
    assert strength(res, GAIN, tied, keep_rank) < strength(res, MASS, tied, keep_rank)


def _is_flow(key: str) -> bool:
    return key.endswith(".valve.rated_flow")


def test_the_flow_gain_goes_only_when_nothing_else_is_left_to_go():
    """The valve flow gain is the baseline: in a closed-loop record without pressures it, the supply
    and the sensor gain can all be unidentified together (each |value/sigma| < 1), and the weakest
    by its own ratio may be the flow gain; the others go first, and the flow gain, refitted alone,
    is then identified (a hanging cylinder's valve 60 % larger than its spec: with the flow gain
    dropped first the calibration ended at nominal and the deadband was missed)."""
    ps = "supply.pressure"
    flow, gain, supply = FreeParameter(FLOW, 1e-5, 1e-3), FreeParameter(GAIN, 0.5, 2.0), FreeParameter(ps, 1e7, 2e7)
    first = _scripted([flow, gain, supply], {FLOW: 2e-4, GAIN: 1.0, ps: 1.5e7},
                      {FLOW: 2e-4 / 0.5, GAIN: 1.0 / 0.8, ps: 1.5e7 / 0.9})
    second = _scripted([flow, supply], {FLOW: 2.2e-4, ps: 1.5e7}, {FLOW: 2.2e-4 / 0.7, ps: 1.5e7 / 0.6})
    third = _scripted([flow], {FLOW: 2.4e-4}, {FLOW: 2.4e-4 / 40.0})
    script = [second, third]
    keep, final, dropped = eliminate([flow, gain, supply], first, identifiability, lambda k, c: script.pop(0),
                                     keep_rank, last=_is_flow)
    assert list(dropped) == [GAIN, ps] and [fp.key for fp in keep] == [FLOW] and final is third
    # without the rule the flow gain, weakest by its ratio, goes first
    settled = _scripted([gain, supply], {GAIN: 1.0, ps: 1.5e7}, {GAIN: 0.01, ps: 1e4})
    _, _, dropped = eliminate([flow, gain, supply], first, identifiability, lambda k, c: settled, keep_rank)
    assert list(dropped) == [FLOW]
    # beside identified parameters a failing flow gain stays; at a range end it goes like any other
    beside = _scripted([flow, gain], {FLOW: 2e-4, GAIN: 1.0}, {FLOW: 2e-4 / 2.0, GAIN: 0.01})
    keep, final, dropped = eliminate([flow, gain], beside, identifiability, lambda k, c: None, keep_rank, last=_is_flow)
    assert [fp.key for fp in keep] == [FLOW, GAIN] and dropped == {} and final is beside
    at_end = _scripted([flow, gain], {FLOW: 1e-3, GAIN: 1.0}, {FLOW: 1e-5, GAIN: 0.01})
    alone = _scripted([gain], {GAIN: 1.0}, {GAIN: 0.01})
    keep, _, dropped = eliminate([flow, gain], at_end, identifiability, lambda k, c: alone, keep_rank, last=_is_flow)
    assert [fp.key for fp in keep] == [GAIN] and "at the upper end" in dropped[FLOW][0]
    # and when it is all that is left, it goes too
    only = _scripted([flow], {FLOW: 2e-4}, {FLOW: 2e-4 / 0.5})
    keep, _, dropped = eliminate([flow], only, identifiability, lambda k, c: None, keep_rank, last=_is_flow)
    assert keep == [] and list(dropped) == [FLOW]


def test_a_flow_gain_kept_below_three_sigma_says_so_and_what_it_carries():
    from sim_core.identification.calibration import mark_baseline

    rows = [{"parameter": FLOW, "identified": True}, {"parameter": MASS, "identified": True},
            {"parameter": GAIN, "identified": False, "not_identified_because": "|value/sigma| = 0.8 < 3"}]
    mark_baseline(rows, {FLOW: "|value/sigma| = 1.2 < 3", MASS: "|value/sigma| = 2 < 3"}, [GAIN])
    assert rows[0]["note"] == "kept as the baseline (|value/sigma| = 1.2 < 3)" and rows[0]["conditional_on"] == [GAIN]
    assert "note" not in rows[1] and "note" not in rows[2]          # only the baseline, only when weak
    rows = [{"parameter": FLOW, "identified": True}]
    assert "note" not in mark_baseline(rows, {FLOW: None}, [GAIN])[0]


def test_a_correlated_partner_the_kept_one_cannot_stand_in_for_stays():
    """A supply pressure and a load the record cannot tell apart (correlation 0.995): the supply goes,
    and the load, refitted alone, carries both. Where that pushes the load to an end of its range at a
    cost the record rejects (a boom's tip load twice its spec's and the supply 13 % low: alone the
    load needs more than its range), the supply stays, flagged, and both keep their fitted values;
    where the cost barely rises, the supply goes as before."""
    ps = "supply.pressure"
    flow, supply, mass = FreeParameter(FLOW, 1e-5, 1e-3), FreeParameter(ps, 9.8e6, 1.61e7), FreeParameter(MASS, 20.0, 85.0)
    corr = np.array([[1.0, 0.1, 0.1], [0.1, 1.0, 0.995], [0.1, 0.995, 1.0]])
    first = oe.FitResult([flow, supply, mass], {FLOW: 4e-4, ps: 1.0e7, MASS: 60.0}, 1.0,
                         sigma={FLOW: 1e-6, ps: 1e5, MASS: 1.0}, correlation=corr, cost_scale=0.01)
    assert identifiability(first)[ps].startswith("correlation") and identifiability(first)[MASS] is None

    def alone(cost):        # the load refitted with the supply at nominal: at its range's end
        return oe.FitResult([flow, mass], {FLOW: 3.5e-4, MASS: 85.0}, cost, sigma={FLOW: 1e-6, MASS: 1.0},
                            cost_scale=0.01)

    restored = oe.FitResult([flow, supply, mass], {FLOW: 4e-4, ps: 1.0e7, MASS: 60.0}, 1.0,
                            sigma={FLOW: 1e-6, ps: 1e5, MASS: 1.0}, correlation=corr, cost_scale=0.01)
    script = [alone(1.5), restored]
    asked = []

    def refit(keep, current):
        asked.append([fp.key for fp in keep])
        return script.pop(0)

    notes: dict[str, str] = {}
    keep, final, dropped = eliminate([flow, supply, mass], first, identifiability, refit, keep_rank,
                                     last=_is_flow, together=jointly_identified, protected=notes)
    assert [fp.key for fp in keep] == [FLOW, ps, MASS] and dropped == {} and final is restored
    assert asked == [[FLOW, MASS], [FLOW, ps, MASS]]
    assert notes[ps].startswith("kept although correlation") and MASS in notes[ps]
    assert notes[MASS].startswith(f"fixed together with {ps}")
    # the cost rises by less than the 3-sigma level (9 x 0.01): the supply goes, then the load at its end
    script = [alone(1.05), oe.FitResult([flow], {FLOW: 3.5e-4}, 1.2, sigma={FLOW: 1e-6}, cost_scale=0.01)]
    notes = {}
    keep, final, dropped = eliminate([flow, supply, mass], first, identifiability, lambda k, c: script.pop(0),
                                     keep_rank, last=_is_flow, together=jointly_identified, protected=notes)
    assert list(dropped) == [ps, MASS] and [fp.key for fp in keep] == [FLOW] and notes == {}


def test_only_the_partner_of_the_pushed_parameter_stays():
    """A sensor offset dropped for its correlation with the sensor's gain does not stand in for a load
    pushed to its range's end (on a boom's flow-saturation record it stayed at -0.3 rad beside a load
    at its end, and a valve asymmetry and an offset were named); the supply tied to that load does."""
    from sim_core.identification.elimination import correlated_with, partners_needed

    ps = "supply.pressure"
    supply, offset, mass = FreeParameter(ps, 9.8e6, 1.61e7), FreeParameter(OFFSET, -0.5, 0.5), FreeParameter(MASS, 20.0, 85.0)
    before = oe.FitResult([supply, offset, mass], {ps: 1e7, OFFSET: -0.3, MASS: 60.0}, 1.0, cost_scale=0.01)
    after = oe.FitResult([mass], {MASS: 85.0}, 1.5, cost_scale=0.01)
    pushed = {MASS: "at the upper end of its range [20, 85]: ..."}
    tied_to_gain = {OFFSET: f"correlation -0.982 with {GAIN}: the record cannot tell them apart"}
    tied_to_load = {ps: f"correlation +0.993 with {MASS}: the record cannot tell them apart"}
    assert correlated_with(tied_to_gain[OFFSET]) == GAIN and correlated_with("|value/sigma| = 1 < 3") is None
    assert partners_needed(before, after, tied_to_gain, lambda r: pushed, [offset], [mass], jointly_identified) is None
    got = partners_needed(before, after, {**tied_to_gain, **tied_to_load}, lambda r: pushed, [supply, offset], [mass],
                          jointly_identified)
    assert got == ([mass], [supply])
