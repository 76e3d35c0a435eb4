"""The decision rules of ``diagnose``, as small pure functions over candidate scores.

Nothing here simulates: the scores arrive in :class:`Evaluation` objects and the steps that need the
simulator (fit a round of candidates, score a model, refit without an effect, refit the final model)
are passed in as callables. selection.py and diagnosis.py wire the real, simulator-based ones; the
tests (tests/test_decision_rules.py) wire synthetic ones, so each rule can be checked on its own.

The rules, in the order they apply:

* acceptance (:func:`judge`): gain >= max(2 points, 3 x the noise spread of the gain); BIC improves;
  no parameter on a search bound other than the one where the effect vanishes; at least one
  parameter more than 3 sigma from "no effect"; on a closed-loop record (scored with the angle
  restarted from the record) the channels that do not integrate must not lose more than 0.5 points
  on average (:func:`drift_stand_in`);
* recalibration (:func:`recalibration_kept`): once an effect is named, the calibration is redone
  with it on the estimation data; the redone one is kept unless it scores more than 2 points lower
  on the validation data (it fitted what the estimation window alone shows);
* forward selection (:func:`forward`): each round every remaining candidate is refitted with what
  is accepted (a large effect masks the others), the passing one with the largest gain joins; stop
  when nothing passes, at ``max_effects`` (3 per diagnosed joint), or when every joint's score is
  within 2 points of its noise ceiling;
* below the floor (:func:`best_explaining`): when nothing passes while the model misses the record
  (more than 2 points under its noise ceiling, or its position reading more than 2 noises beyond
  the noise, :func:`position_misfit`; residual tests failing), a candidate that fails only the
  2-point floor, closes 85 % of the distance to the ceiling on its joints and whitens the residual
  joins;
* masked pairs (:func:`rank_pairs`, :func:`forward`): when no single candidate passes but the model's
  residual tests fail, the most promising pairs (by the sum of their single validation gains and,
  taking turns, by the sum of their estimation-fit improvements; at most 15) are fitted jointly; a pair that passes (each member identified) joins as two effects named together;
* backward pass (:func:`backward`): an accepted effect whose removal (the others refitted) costs
  less than 2 points on the joints it acts on is dropped (an early pick can stand in for effects
  named later); a pair named together is removed together (each alone is absorbed by the refit, by
  definition);
* exchange pass (:func:`exchange`): each effect named before the last is refitted against the
  strongest rivals of its round once the later effects are in the model; a rival that passes there
  and beats it by 0.5 points (or 3 x the rival's noise spread) on the joints either acts on takes
  its place (a greedy first pick
  can be the best single stand-in for a cause that only shows beside an effect named later);
* final check (:func:`final_check`): in the refitted final model each named effect must still be
  worth 2 points, else the weakest is dropped and the rest refitted; when the search had stopped
  near the noise ceiling because of a dropped effect, the pair search it skipped runs then
  (:func:`pairs_after_a_drop`), and a passing pair goes through the final check in turn;
* ambiguity (:func:`rivalry`): a runner-up of another effect within 20 % of the winner's gain, on
  the winner's joints, flags the choice ambiguous, with the measurement that would decide
  (``decided_by``);
* verdict (:func:`verdict`, :func:`unexplained_reasons`): ``unexplained_discrepancy`` when the model
  (extended or not) still misses the record by far (an angle fit below zero, more than 10 points
  under the noise ceiling with failing residual tests, or the velocity more than 10 points under
  its ceiling with a white residual; "far" also needs a misfit beyond the noise of twice the noise,
  :func:`far`), or when the named effects leave a chamber
  pressure more than 2 points under its ceiling having closed less than 85 % of the baseline's
  misfit on it, or when nothing is named while a joint's score sits more than 2 points and one
  noise (:func:`worth_naming`) under its ceiling with failing residual tests (a misfit the bank has
  no name for), ``discrepancy`` when
  effects are named, ``no_significant_discrepancy`` otherwise.

Every rule that weighs points weighs them on the joints in question (the candidate's, the effect's,
each joint's own ceiling): on a record of ten joints the mean moves by a tenth of what one joint's
effect moves its own. On a record of one joint each is the record's score.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from .candidates import Candidate, decider

THRESHOLD_POINTS = 2.0      # smallest validation gain that counts (research note: 2 points)
NOISE_FACTOR = 3.0          # ... or 3 x the noise spread of the gain, when larger
SIGNIFICANCE = 3.0          # |value - null| / sigma of an identified parameter
AMBIGUITY = 0.8             # runner-up gain above this share of the winner's: ambiguous
MAX_EFFECTS = 3             # effects named per diagnosed joint (selection.effect_limit)
MAX_PAIRS = 15              # joint fits of two candidates tried when no single one passes
FAR_POINTS = 10.0           # a model this far (score points) below its noise ceiling misses the record ...
FAR_NOISE = 2.0             # ... when its misfit beyond the noise is also this many times the noise (RMS)
FAR_MARK = f"more than {FAR_POINTS:g} points and {FAR_NOISE:g} noises"   # the mark, as the reasons say it
WORTH_NOISE = 1.0           # a misfit (beyond the noise, RMS) under this many noises is not worth naming
WHITE_MISS_CHANNELS = ("velocity",)   # far off with a white residual: a disturbance on the measured position
POSITION_CHANNELS = ("angle", "restarted")   # the position reading: a misfit there in noises is a model's
DRIFT_LOSS_POINTS = 0.5     # mean loss of the local channels that marks a stand-in for the replay's drift
LOCAL_CHANNELS = ("restarted", "velocity")   # channels an open-loop replay does not integrate errors into
EXPLAINED_SHARE = 0.85      # share of the baseline's chamber-pressure misfit a named cause must close
EXCHANGE_RIVALS = 2         # runners-up of an effect's round refitted in its place once later effects are named
EXCHANGE_POINTS = 0.5       # score points (or 3 x the rival's noise spread) a rival must win by to take the place
OTHER_STARTS = 2            # first-round runners-up a forward path starts from when the greedy path misses the record

NAMED = "discrepancy"
NONE = "no_significant_discrepancy"
UNEXPLAINED = "unexplained_discrepancy"


@dataclass
class Evaluation:
    """One candidate fitted and scored on the validation data (gains in NRMSE points)."""

    candidate: Candidate
    values: dict[str, float]                  # every fitted key (effect and calibration)
    sigma: dict[str, float]
    ci95: dict[str, list[float]]
    cost: float
    fits: dict[str, dict[str, float]]         # validation fits per joint
    gain: float = 0.0
    gain_channels: dict[str, float] = field(default_factory=dict)
    spread: float = 0.0
    bic_delta: float = 0.0
    significance: dict[str, float] = field(default_factory=dict)
    bounds: dict[str, str] = field(default_factory=dict)
    reasons: list[str] = field(default_factory=list)
    sims: int = 0
    round: int = 1
    outputs: Any = None
    base_score: float = math.nan              # the model it is compared with, on the same joints
    pair: Evaluation | None = None            # a member of a pair named together: the pair's evaluation
    in_place_of: Evaluation | None = None     # a rival of the exchange pass: the accepted effect it was fitted for
    held_at_default: dict[str, float] = field(default_factory=dict)   # parameters the record does not show (simpler_parameters)
    # every acceptance rule but the 2-point floor holds (the gain is above 3 x its noise spread): such a
    # candidate may still be the one that explains a record the model misses (best_explaining)
    short_of_floor: bool = False
    explains_record: str | None = None        # why it was accepted below the floor (best_explaining), else None
    # parameters freed beyond their declared ranges that explain the record as well in its place
    # (stand_in): the record does not tell the effect from them
    as_well_beyond_range: list[dict] = field(default_factory=list)

    @property
    def accepted_ok(self) -> bool:
        return not self.reasons

    @property
    def key(self) -> tuple[str, str | None]:
        return self.candidate.effect, self.candidate.joint

    @property
    def explained_pct(self) -> float:
        return residual_explained_pct(self.gain, self.base_score)

    def effect_params(self) -> dict[str, float]:
        """The candidate's own parameters (effect keys), by parameter name; those held at their
        default (:func:`simpler_parameters`) at that value."""
        out = {fp.key.split(".")[-1]: self.values[fp.key] for fp in self.candidate.free}
        return {**out, **self.held_at_default}


# ---- readable scale ---------------------------------------------------------------------------------
def residual_explained_pct(gain: float, base_score: float) -> float:
    """Share (percent) of the baseline residual a gain removes. A score is a mean of NRMSE fits
    100 (1 - |r| / |y - mean y|), so a gain of g points on a base score b shrinks the normalised
    residual 1 - b/100 by g/100: the share is 100 g / (100 - b). Thousands of points on a runaway
    baseline read as a share near 100 %; NaN when the base is unknown or already perfect."""
    if not (math.isfinite(gain) and math.isfinite(base_score)) or base_score >= 100.0:
        return math.nan
    return 100.0 * gain / (100.0 - base_score)


# ---- acceptance ---------------------------------------------------------------------------------------
def required_gain(spread: float) -> float:
    """The gain a candidate must reach: 2 points, or 3 x the gain's noise spread when larger."""
    return max(THRESHOLD_POINTS, NOISE_FACTOR * spread)


def null_side(lower: float, upper: float, null: float | None) -> str | None:
    """Which search bound is the value where the effect vanishes ('lower'/'upper'), if either."""
    if null is None or math.isnan(null):
        return None
    if null <= lower + 1e-12 * max(1.0, abs(lower)):
        return "lower"
    if null >= upper - 1e-12 * max(1.0, abs(upper)):
        return "upper"
    return None


def judge(ev: Evaluation, at_bound: dict[str, str]) -> None:
    """Apply the acceptance rules to ``ev``; ``at_bound`` names the parameters the fit left on a
    search bound ('lower'/'upper'). The reasons a candidate fails are kept for the report."""
    significant = 0
    for fp in ev.candidate.free:
        key = fp.key
        sig = ev.sigma.get(key, math.inf)
        ref = 0.0 if fp.null is None or not math.isfinite(fp.null) else fp.null
        t = abs(ev.values[key] - ref) / sig if sig > 0 and math.isfinite(sig) else 0.0
        ev.significance[key] = t
        bound = at_bound.get(key)
        if bound is not None:
            ev.bounds[key] = bound
            if bound == null_side(fp.lower, fp.upper, fp.null):
                continue                      # at the value where the effect vanishes: absent
            ev.reasons.append(f"{key.split('.')[-1]} at its {bound} search bound")
            continue
        if t > SIGNIFICANCE:
            significant += 1
    if not significant and not any("search bound" in r for r in ev.reasons):
        ev.reasons.append(f"no parameter differs from 'no effect' by {SIGNIFICANCE:g} sigma")
    elif significant:
        for m in getattr(ev.candidate, "members", ()):     # a pair: each member must be identified
            if not any(ev.significance[fp.key] > SIGNIFICANCE and fp.key not in ev.bounds for fp in m.free):
                ev.reasons.append(f"{m.label}: no parameter differs from 'no effect' by {SIGNIFICANCE:g} sigma")
    if not math.isfinite(ev.gain):
        ev.reasons.append("the fitted model cannot be simulated on the validation data (the state diverged)")
        return
    need = required_gain(ev.spread)
    if ev.gain < need:
        ev.reasons.append(f"validation gain {ev.gain:.2f} below {need:.2f} points")
        ev.short_of_floor = need == THRESHOLD_POINTS
    if not ev.bic_delta < 0:
        ev.reasons.append(f"BIC does not improve ({ev.bic_delta:+.1f})")
    loss = drift_stand_in(ev.gain_channels)
    if loss is not None:
        ev.reasons.append(f"it gains on the whole-record angle while the channels that do not integrate (velocity, "
                          f"angle restarted from the record) lose {loss:.2f} points: it stands in for the drift of "
                          f"the closed-loop record's open-loop replay")


def drift_stand_in(gain_channels: dict[str, float]) -> float | None:
    """The mean loss (points) of the local channels when a candidate stands in for a replay's drift;
    None otherwise. On a closed-loop record the model replays the logged command open loop, and any
    error in that command (its timing between samples) integrates into the angle over the whole
    record, while the real loop pulled it back; a candidate can buy some of that drift back with a
    bias (a slight asymmetry, an offset) and gain on the whole-record angle only. What the rig does
    shows in the channels that do not integrate, the velocity and the angle restarted from the
    record every few loop time constants: a cause of the rig does not make those worse. Only where
    the record is scored with the restarted angle (closed loop), and where the whole-record angle gains."""
    if "restarted" not in gain_channels or not gain_channels.get("angle", 0.0) > 0.0:
        return None
    loss = -float(np.mean([gain_channels[c] for c in LOCAL_CHANNELS if c in gain_channels]))
    return loss if loss > DRIFT_LOSS_POINTS else None


# ---- forward selection ----------------------------------------------------------------------------------
def best_passing(evals: list[Evaluation]) -> Evaluation | None:
    """The candidate that joins the model: the largest gain among those that pass."""
    ok = [e for e in evals if e.accepted_ok]
    return max(ok, key=lambda e: e.gain) if ok else None


def best_explaining(evals: list[Evaluation], score: float, ceiling: float, explains: Callable,
                    gap_on: Callable | None = None, position_noises: float | None = None) -> Evaluation | None:
    """The candidate that explains a record the model misses although its gain is under the 2-point
    floor, or None. Called where no candidate of a round passes while the model misses the record
    (the residual tests fail and its ``score`` is more than the threshold under its noise
    ``ceiling``): a misfit worth naming, so a candidate that removes it is its cause even where the
    rest of the misfit above the noise is smaller than the floor (a baseline 2.2 points under its
    ceiling, a leak gaining 1.99 of them). It must pass every other acceptance rule (3 x its noise
    spread, BIC, identified parameters, bounds), close EXPLAINED_SHARE of the distance to the ceiling,
    and ``explains(ev)`` must hold: with it the residual tests pass and the model does not miss the
    record. This is forward selection's side of what the backward pass and the final check already
    do (an effect without which the model misses the record is kept whatever its points); without
    it the verdict said the bank had nothing for a misfit that one of its candidates removes. The
    largest gain among those wins; the floor's reason is replaced by ``explains_record``.
    ``gap_on(ev)``: the model's distance to the noise ceiling on the joints ``ev`` acts on, the scale
    its gain is taken on (a leak on one of four joints closes its own joint's distance, a quarter of
    the four's mean); None: ``ceiling - score``. ``position_noises``: given where the model is
    within the floor of its ceiling in points but misses its position reading by that many noises
    (:func:`position_misfit`), which the reason then says."""
    def gap_of(e):
        return ceiling - score if gap_on is None else gap_on(e)

    ok = [e for e in evals if e.short_of_floor and len(e.reasons) == 1 and e.gain >= EXPLAINED_SHARE * gap_of(e)
          and explains(e)]
    if not ok:
        return None
    best = max(ok, key=lambda e: e.gain)
    gap = gap_of(best)
    missed = (f"{gap:.2f} points under the noise ceiling" if position_noises is None else
              f"{gap:.2f} points under the noise ceiling, its position reading a misfit of {position_noises:.1f} "
              f"noises beyond the noise")
    best.explains_record = (f"accepted below the {THRESHOLD_POINTS:g}-point floor ({best.gain:+.2f} points): the model "
                            f"without it misses the record (its residual tests fail, {missed}), with it the residual "
                            f"tests pass ({100 * best.gain / gap:.0f} % of that distance closed)")
    best.reasons.clear()
    return best


def recalibration_kept(before: float, after: float) -> bool:
    """Whether a calibration redone with a newly named effect replaces the model as it was: the
    validation scores of the model before and after. Both were fitted on the estimation data; a redone
    calibration that frees more parameters can fit that window better and predict the rest worse (a
    sensor offset fitted to millimetres of structural misfit puts the end stop centimetres off, which
    only a later end-stop contact shows). More than the acceptance threshold lost: not kept."""
    return after >= before - THRESHOLD_POINTS


def mean_score(fits: dict[str, dict[str, float]]) -> float:
    """A model's validation score: the mean over joints of their decision scores."""
    return score_over(fits)


def score_over(fits: dict[str, dict[str, float]], joints: list[str] | None = None) -> float:
    """The mean decision score over ``joints`` (None: every joint): the scale of a decision about an
    effect, on the joints it acts on."""
    return float(np.mean([fits[j]["score"] for j in (fits if joints is None else joints)]))


def near_ceiling(score: float, ceiling: float) -> bool:
    """Within the threshold of the noise ceiling nothing more can be shown: stop searching."""
    return ceiling - score < THRESHOLD_POINTS


@dataclass
class Forward:
    accepted: list[Evaluation]
    rounds: list[list[Evaluation]]
    model: Any
    stopped: str
    pairs: list[list[Evaluation]] = field(default_factory=list)    # the pair fits of each pair search
    at_ceiling: bool = False                  # stopped because the model came within the threshold of its ceiling


def rank_pairs(evals: list[Evaluation], max_pairs: int = MAX_PAIRS) -> list[tuple[Evaluation, Evaluation]]:
    """The pairs of a round's single candidates worth fitting jointly, most promising first. Two orders
    take turns: by the sum of the members' single validation gains (a masked effect still moves the
    fit a little; one absorbed by the calibration gains about nothing, one cancelled by its partner
    may lose), and by the sum of their improvements of the estimation fit (``bic_delta``): alone, a
    member of a pair can explain much of the estimation data and still lose on the validation part,
    where the share it cannot explain without its partner (a drift that two effects cause together)
    carries it off. Two candidates of the same effect and joint, or one whose fit diverged, make no
    pair. At most ``max_pairs``."""
    ok = [e for e in evals if math.isfinite(e.gain)]
    pairs = [(a, b) for i, a in enumerate(ok) for b in ok[i + 1:] if a.key != b.key]
    by_gain = sorted(pairs, key=lambda p: -(p[0].gain + p[1].gain))

    def fit_gain(p):       # ties (equal fits) in the gain order
        return (sum(e.bic_delta if math.isfinite(e.bic_delta) else math.inf for e in p), -(p[0].gain + p[1].gain))

    by_fit = sorted(pairs, key=fit_gain)
    out: list[tuple[Evaluation, Evaluation]] = []
    seen: set[tuple[int, int]] = set()
    for turn in zip(by_gain, by_fit):
        for p in turn:
            if (id(p[0]), id(p[1])) not in seen:
                seen.add((id(p[0]), id(p[1])))
                out.append(p)
    return out[:max_pairs]


def member_evaluations(pair_ev: Evaluation) -> list[Evaluation]:
    """A pair that passed, as one Evaluation per member (its own candidate, the pair's fit and gain)."""
    out = []
    for m in pair_ev.candidate.members:
        keys = {fp.key for fp in m.free}
        out.append(Evaluation(m, dict(pair_ev.values), dict(pair_ev.sigma), dict(pair_ev.ci95), pair_ev.cost,
                              pair_ev.fits, gain=pair_ev.gain, gain_channels=dict(pair_ev.gain_channels),
                              spread=pair_ev.spread, bic_delta=pair_ev.bic_delta,
                              significance={k: v for k, v in pair_ev.significance.items() if k in keys},
                              bounds={k: v for k, v in pair_ev.bounds.items() if k in keys}, sims=pair_ev.sims,
                              round=pair_ev.round, outputs=pair_ev.outputs, base_score=pair_ev.base_score,
                              pair=pair_ev))
    return out


def forward(cands: list[Candidate], model, *, evaluate_round: Callable, extend: Callable, score: Callable,
            ceiling: float, max_effects: int = MAX_EFFECTS, log=None, evaluate_pairs: Callable | None = None,
            misfit: Callable | None = None, first: tuple[list[Evaluation], Evaluation] | None = None,
            explains: Callable | None = None, short_of_ceiling: Callable | None = None,
            gap_on: Callable | None = None, position_noises: Callable | None = None) -> Forward:
    """Greedy forward selection, with the masked-pair search.

    ``evaluate_round(pool, model, accepted, round)`` fits and judges every candidate of ``pool`` on
    ``model`` (``accepted``: [(candidate, params)] already in it) and returns their Evaluations;
    ``extend(model, ev)`` is ``model`` with ``ev``'s candidate (a single or a pair) at its fitted
    values; ``score(model)`` its validation score. ``evaluate_pairs(pairs, model, accepted, round)``
    (pairs: :func:`rank_pairs`) fits and judges pairs jointly; it is called when no single candidate
    of a round passes, the model is not near its noise ceiling and ``misfit(model)`` (its residual
    tests fail) holds. None: no pair search. ``first``: (the first round's Evaluations, the one to
    take from them) instead of fitting that round and taking its best (:func:`other_starts`).
    ``explains(ev)``: whether with ``ev`` the residual tests pass and the model no longer misses the
    record; under the same conditions as the pair search, and before it, a single candidate that
    explains the record below the 2-point floor is taken (:func:`best_explaining`). None: not tried.
    ``short_of_ceiling(model)``: the points by which the joint furthest below its own noise ceiling
    misses it; the search goes on while that is the threshold or more (a deadband on one of ten
    joints is worth a tenth of its points to their mean). None: the mean score against ``ceiling``.
    ``gap_on(model, ev)``: that distance on the joints ``ev`` acts on, for :func:`best_explaining`.
    ``position_noises(model)``: its position reading's misfit beyond the noise, in noises
    (:func:`position_misfit`); more than FAR_NOISE with failing residual tests, the model misses the
    record for :func:`best_explaining` even within the floor of its ceiling in points (a large
    motion makes 2 points many noises); the pair search keeps to the points. None: not used."""
    log = log or (lambda msg: None)

    def near(model, s):
        return near_ceiling(s, ceiling) if short_of_ceiling is None else short_of_ceiling(model) < THRESHOLD_POINTS

    accepted: list[Evaluation] = []
    rounds: list[list[Evaluation]] = []
    pairs_tried: list[list[Evaluation]] = []
    pool = list(cands)
    stopped = "no candidate passed"
    at_ceiling = False
    for r in range(1, max_effects + 1):
        if r > 1:
            s = score(model)
            if near(model, s):
                stopped = f"score {s:.1f} within {THRESHOLD_POINTS:g} points of its noise ceiling {ceiling:.1f}"
                at_ceiling = True
                break
        if not pool:
            stopped = "no candidates left"
            break
        have = [(e.candidate, e.effect_params()) for e in accepted]
        if r == 1 and first is not None:
            evals, best = first
        else:
            evals = evaluate_round(pool, model, have, r)
            best = best_passing(evals)
        rounds.append(evals)
        if best is None:
            # the model misses the record: far from its noise ceiling, the residual tests failing
            s = score(model)
            close = near(model, s)
            missed = not close and (misfit is None or misfit(model))
            # within the floor in points, the position reading may still be missed by many noises
            noises = position_noises(model) if close and position_noises is not None and misfit is not None else None
            if noises is not None and not (noises > FAR_NOISE and misfit(model)):
                noises = None
            if explains is not None and misfit is not None and (missed or noises is not None):
                best = best_explaining(evals, s, ceiling, explains,
                                       None if gap_on is None else (lambda e, m=model: gap_on(m, e)), noises)
        if best is None:
            stopped = "no candidate passed" if r == 1 else "no further candidate passed"
            if evaluate_pairs is None or len(accepted) + 2 > max_effects or not missed:
                break
            pairs = rank_pairs(evals)
            if not pairs:
                break
            pevals = evaluate_pairs(pairs, model, have, r)
            pairs_tried.append(pevals)
            best = best_passing(pevals)
            if best is None:
                stopped += f", alone or in {len(pevals)} pair{'s' if len(pevals) != 1 else ''}"
                break
            log(f"round {r}: accepted the pair {best.candidate.label} ({best.gain:+.2f} points; neither passes alone)")
            accepted.extend(member_evaluations(best))
        else:
            log(f"round {r}: accepted {best.candidate.label} ({best.gain:+.2f} points"
                + ("; below the floor, it explains the record the model misses)" if best.explains_record else ")"))
            accepted.append(best)
        model = extend(model, best)
        done = {e.key for e in accepted}
        # a large effect masks the others: every remaining candidate gets another chance
        pool = [c for c in cands if (c.effect, c.joint) not in done]
        if len(accepted) >= max_effects:      # a pair can reach the limit before its round count does
            stopped = f"reached {max_effects} effects"
            break
    return Forward(accepted, rounds, model, stopped, pairs_tried, at_ceiling)


def other_starts(fw: Forward, k: int = OTHER_STARTS) -> list[Evaluation]:
    """The first round's passing candidates other than the one greedy selection took there, largest
    gain first (at most ``k``)."""
    if not fw.rounds or not fw.accepted:
        return []
    taken = {e.key for e in fw.accepted if e.round == 1}
    ok = [e for e in fw.rounds[0] if e.accepted_ok and e.key not in taken]
    return sorted(ok, key=lambda e: -e.gain)[:k]


def restart(fw: Forward, *, rerun: Callable, score: Callable, misses: Callable | None = None,
            to_start: Callable | None = None, checkpoint: Callable | None = None, log=None,
            k: int = OTHER_STARTS) -> Forward:
    """Greedy selection takes the first round's best single with nothing else in the model, and the
    rest of the path follows from it. That single can stand for two others, each of which fits worse
    alone than it (a leak for a spool overlap with weaker retract edges: the overlap alone makes the
    model worse). When the greedy path's model misses the record (``misses(model)``:
    :func:`misses_record` on its validation fits), forward selection runs again from each of the
    first round's next best passing candidates (:func:`other_starts`, at most ``k``; it stops at the
    first path whose model no longer misses the record), and the path whose model scores highest is
    kept when it beats the greedy one by EXCHANGE_POINTS.

    ``rerun(ev)``: forward selection with ``ev`` taken in the first round. ``to_start()``: puts the
    search's state (what forward selection and recalibration changed) back as it was before the
    greedy path; ``checkpoint()`` returns such a callable for the state at its call. Returns the
    path kept, with the state it left."""
    log = log or (lambda msg: None)
    if misses is None or not fw.accepted or not misses(fw.model):
        return fw
    starts = other_starts(fw, k)
    if not starts:
        return fw
    s0 = score(fw.model)
    best, best_s = fw, s0
    keep = checkpoint() if checkpoint is not None else None
    for ev in starts:
        if to_start is not None:
            to_start()
        log(f"the path from {fw.accepted[0].candidate.label} misses the record (score {s0:.1f}): forward "
            f"selection again from {ev.candidate.label}")
        alt = rerun(ev)
        s = score(alt.model)
        if s > best_s + EXCHANGE_POINTS:
            best, best_s = alt, s
            keep = checkpoint() if checkpoint is not None else None
        if not misses(alt.model):
            break
    if keep is not None:
        keep()
    if best is not fw:
        best.stopped += (f"; started from {best.accepted[0].candidate.label} in place of "
                         f"{fw.accepted[0].candidate.label}, whose path missed the record (score {s0:.1f} -> "
                         f"{best_s:.1f})")
    return best


def misses_record(fits: dict[str, dict[str, float]], ceiling: float, channel_ceilings: dict[str, dict[str, float]],
                  residual_fails: bool, base_fits: dict[str, dict[str, float]] | None = None) -> bool:
    """Whether a model with these validation fits (joint -> channel -> fit, with its "score") would be
    reported as not explaining the record (:func:`unexplained_reasons`' rules on the fits alone: an
    angle fit below zero, the score or one channel missing its noise ceiling by far (:func:`far`)
    while the residual tests fail; with ``base_fits``, the baseline's fits, also a chamber pressure
    whose misfit the model's effects leave mostly open). The velocity far off with a white
    residual is not counted: that is a disturbance on the measured signal, which no other path of
    effects explains either."""
    joints = list(fits)
    return bool(unexplained_reasons(
        angle_fits={j: fits[j]["angle"] for j in joints}, score=mean_score(fits), ceiling=ceiling,
        residual_fails=residual_fails,
        channel_fits={j: {c: v for c, v in fits[j].items() if c != "score"} for j in joints},
        channel_ceilings=channel_ceilings, base_channel_fits=base_fits, disturbance=False))


def pairs_after_a_drop(kept: list[Evaluation], dropped: list[Evaluation], fw: Forward, model, *,
                       evaluate_pairs: Callable | None, score: Callable, ceiling: float, misfit: Callable | None = None,
                       max_effects: int = MAX_EFFECTS, log=None,
                       short_of_ceiling: Callable | None = None) -> tuple[list[Evaluation], Evaluation | None]:
    """The pair search that forward selection skipped because an effect brought the model within the
    threshold of its noise ceiling, run once the final check has dropped that effect (the reason to
    stop is gone with it). ``model``: the search's model without the dropped effects, ``kept``: what the
    final check kept. The pairs come from the round the first dropped effect joined in, the dropped
    one among them (not worth the threshold alone, it may be with a partner), under the same
    conditions as in :func:`forward` (the model not near its ceiling, its residual tests failing,
    room for two more). An effect the exchange pass put in counts from the round of the one it
    replaced. ``short_of_ceiling(model)``: as in :func:`forward` (the joint furthest below its own
    ceiling); None: the mean score against ``ceiling``. Returns the pair evaluations and the passing
    pair's evaluation (or None)."""
    log = log or (lambda msg: None)
    if not dropped or not fw.at_ceiling or evaluate_pairs is None or len(kept) + 2 > max_effects:
        return [], None
    short = ceiling - score(model) if short_of_ceiling is None else short_of_ceiling(model)
    if short < THRESHOLD_POINTS or (misfit is not None and not misfit(model)):
        return [], None
    r = min((ev.in_place_of or ev).round for ev in dropped)
    taken = {e.key for e in kept}
    pairs = [p for p in rank_pairs(fw.rounds[r - 1]) if p[0].key not in taken and p[1].key not in taken]
    if not pairs:
        return [], None
    log(f"the final check dropped {', '.join(e.candidate.label for e in dropped)}: fitting {len(pairs)} pairs")
    pevals = evaluate_pairs(pairs, model, [(e.candidate, e.effect_params()) for e in kept], r)
    return pevals, best_passing(pevals)


# ---- exchange pass ---------------------------------------------------------------------------------------
def exchange_rivals(ev: Evaluation, round_evals: list[Evaluation], accepted: list[Evaluation],
                    k: int = EXCHANGE_RIVALS, dropped: list[Evaluation] = ()) -> list[Evaluation]:
    """The ``k`` candidates of ``ev``'s round with the largest positive gains, other than the effects
    already named and those the backward pass ``dropped`` (judged already beside the ones named)."""
    taken = {e.key for e in accepted} | {e.key for e in dropped}
    rivals = [e for e in round_evals if e.key not in taken and math.isfinite(e.gain) and e.gain > 0]
    return sorted(rivals, key=lambda e: -e.gain)[:k]


def exchange(accepted: list[Evaluation], rounds: list[list[Evaluation]], model, full: float, *,
             refit_without: Callable, evaluate: Callable, score_with: Callable, replace: Callable, score: Callable,
             log=None, scale: Callable | None = None, dropped: list[Evaluation] = ()):
    """Refit each effect named before the last against its round's strongest rivals, with the effects
    named after it in the model: greedy selection takes a round's best single with what the model held
    then, and an effect named later can make a rival the better explanation (a valve asymmetry stands
    for a null offset until the hysteresis beside it is named). The last effect's round already saw
    every other; a pair named together goes as found.

    ``dropped``: the effects the backward pass removed. An effect named in a round after one of those
    was chosen beside it, in a model that no longer holds it (a softened oil named first on a
    closed-loop record, a spool lag beside it, the oil dropped): it is tried too, last or not, against
    the strongest rivals of the round that named the earliest of them as well as its own (there the
    model held what it holds now), a dropped effect never among them.

    ``refit_without(model, ev, rest)`` -> (the model without ``ev``, the rest refitted; its score);
    ``evaluate(candidates, model, rest, round)`` -> their judged Evaluations fitted on that model;
    ``score_with(ev)`` -> the validation score of the model with ``ev``'s fit (every joint, like
    ``full``); ``replace(model, ev)`` -> that model. A rival takes the place when it passes the
    acceptance rules on the model without the effect and its model scores more than
    max(EXCHANGE_POINTS, 3 x its noise spread) above ``full``; ``score(model)`` is then the new
    ``full``. ``scale(model, ev, rival)`` -> (the score of ``model``, that of the rival's model), both
    on the joints either acts on (a rival on the effect's joint of ten wins a tenth of its points on
    the ten's mean); None: ``full`` and ``score_with(rival)``. Each rival's ``in_place_of`` is the
    effect it was fitted for. Returns (model, accepted, the rivals' Evaluations of each effect tried)."""
    log = log or (lambda msg: None)
    accepted = list(accepted)
    tried: list[list[Evaluation]] = []
    last = accepted[-1] if accepted else None
    for ev in list(accepted):
        # the round of the earliest effect dropped before ``ev`` was named (0: none)
        stale = min((e.round for e in dropped if e.round < ev.round), default=0)
        if ev.pair is not None or (ev is last and not stale):
            continue
        rivals = exchange_rivals(ev, rounds[ev.round - 1], accepted, dropped=dropped)
        if stale:
            keys = {e.key for e in rivals}
            rivals += [e for e in exchange_rivals(ev, rounds[stale - 1], accepted, dropped=dropped)
                       if e.key not in keys]
        if not rivals:
            continue
        rest = [e for e in accepted if e is not ev]
        minus, _ = refit_without(model, ev, rest)
        r = len(rounds) + len(tried) + 1
        evals = evaluate([e.candidate for e in rivals], minus, rest, r)
        for e in evals:
            e.in_place_of = ev
        tried.append(evals)
        best = best_passing(evals)
        if best is None:
            continue
        for e in evals:
            if e.accepted_ok and e is not best:
                e.reasons.append(f"{best.candidate.label} gains more in place of {ev.candidate.label}")
        before, s = (full, score_with(best)) if scale is None else scale(model, ev, best)
        margin = max(EXCHANGE_POINTS, NOISE_FACTOR * best.spread)
        if not s - before > margin:
            best.reasons.append(f"in place of {ev.candidate.label} its model scores {s - before:+.2f} points, "
                                f"not more than {margin:.2f}")
            continue
        log(f"exchange: {best.candidate.label} replaces {ev.candidate.label} ({before:.2f} -> {s:.2f} points)")
        ev.reasons.append(f"exchanged for {best.candidate.label}: with the effects named after it in the model, "
                          f"{best.candidate.label} in its place scores {s - before:+.2f} points more")
        accepted = [best if e is ev else e for e in accepted]
        model = replace(minus, best)
        full = score(model)
    return model, accepted, tried


# ---- stand-ins ----------------------------------------------------------------------------------------------
def stand_in(accepted: list[Evaluation], model, full: float, *, stand_ins: Callable, refit_instead: Callable,
             log=None, score_on: Callable | None = None):
    """A named effect must explain the record better than a nominal parameter with its signature (a
    stand-in, calibration.STAND_IN_FOR) calibrated in its place: where the model with the stand-in
    freed instead scores within THRESHOLD_POINTS of ``full``, what the effect explained is a
    calibration finding (links heavier than the URDF says, not a payload). A stand-in that stops at a
    bound of its range (what a nominal parameter may plausibly be off by) does not: the record asks
    for more than a calibration. A stand-in beyond its declared range (``p.declared``: that range,
    beyond_range.BeyondRange) counts only with its value outside that range, and replaces the effect
    only where it explains the record by the threshold better; as well, the effect stays and keeps it
    in ``as_well_beyond_range``.

    ``stand_ins(ev)`` -> the stand-ins of ``ev``'s effect (opaque, e.g. free parameters);
    ``refit_instead(model, ev, rest, p)`` -> (the model without ``ev`` with ``p`` freed and the rest
    refitted, its score, the value ``p`` took, the bound it stops at or None). ``score_on(model, ev)``:
    the score on the joints ``ev`` acts on, the scale its gain was judged on (as in :func:`backward`);
    None: the scores as given. A member of a pair named together stays (the pair was judged as one).
    Returns (model, accepted, [(ev, p, value, its model's score, full)] replaced)."""
    log = log or (lambda msg: None)
    accepted = list(accepted)
    found = []
    for ev in list(accepted):
        if ev.pair is not None:
            continue
        for p in stand_ins(ev):
            rest = [e for e in accepted if e is not ev]
            alt, s, value, bound = refit_instead(model, ev, rest, p)
            loss = full - s if score_on is None or not math.isfinite(s) else score_on(model, ev) - score_on(alt, ev)
            declared = getattr(p, "declared", None)
            if bound is None and declared is not None:
                bound = p.within_declared(value)
            if loss >= THRESHOLD_POINTS or bound is not None:
                log(f"stand-in: {ev.candidate.label} stays ({getattr(p, 'key', p)} = {value:.4g}"
                    + (f" at its {bound} bound" if bound in ("lower", "upper") else f", {bound}" if bound else "")
                    + f", {-loss:+.2f} points)")
                continue
            if declared is not None and -loss < THRESHOLD_POINTS:
                # a parameter beyond the range its user declared, as good but not better: the user's
                # range is a statement about the rig as much as the bank's effects are, so the effect
                # stays and says the record does not tell them apart
                log(f"stand-in: {ev.candidate.label} stays, as well explained by {p.key} = {value:.4g} beyond its "
                    f"declared range ({-loss:+.2f} points)")
                ev.as_well_beyond_range.append({"parameter": p.key, "value": value, "declared_range": list(declared),
                                                "score": round(s, 3), "score_with_effect": round(full, 3)})
                continue
            log(f"stand-in: {ev.candidate.label} replaced by a calibration ({full:.2f} -> {s:.2f} points)")
            ev.reasons.append(f"not named: a calibration in its place ({getattr(p, 'key', p)} = {value:.4g}) explains the "
                              f"record as well ({-loss:+.2f} points; an effect must win by {THRESHOLD_POINTS:g})")
            found.append((ev, p, value, s, full))
            accepted, model, full = rest, alt, s
            break
    return model, accepted, found


def secondary(ev: Evaluation) -> list:
    """The parameters of ``ev``'s effect that :func:`simpler_parameters` tries at their default, last
    to first: all but the first, the effect's principal one (a leak across the piston before one to
    tank, the bulk modulus before its entrained-air softening)."""
    return list(ev.candidate.free[1:])[::-1]


def simpler_parameters(accepted: list[Evaluation], model, full: float, *, default: Callable, refit_held: Callable,
                       log=None, score_on: Callable | None = None):
    """A named effect's secondary parameter must be worth the threshold as the effect is: held at the
    effect's default (``default(ev, p)``: its typical value, none to tank for a leak, or None where it
    has none) with the rest refitted (``refit_held(model, ev, p, value)`` -> (that model, its score,
    its fitted values)), the validation score must lose THRESHOLD_POINTS, or it stays held, as the
    calibration keeps at nominal what the record does not identify. Two parameters the record cannot
    tell apart (a leak across the piston and one to tank, on a record without chamber pressures)
    then give one value for the leak the record shows, in the principal parameter, instead of a split
    the noise decides. ``score_on(model, ev)``: the score on the joints ``ev`` acts on (as in
    :func:`backward`); None: the scores as given. Returns (model, its score, [(ev, parameter, value,
    score with it held)]); each ``ev`` held there keeps ``held_at_default`` and a candidate without
    that parameter."""
    log = log or (lambda msg: None)
    held = []
    for ev in accepted:
        for p in secondary(ev):
            value = default(ev, p)
            if value is None or not math.isfinite(value) or ev.values.get(p.key) == value:
                continue
            alt, s, values = refit_held(model, ev, p, value)
            name = p.key.split(".")[-1]
            loss = full - s if score_on is None or not math.isfinite(s) else score_on(model, ev) - score_on(alt, ev)
            if loss >= THRESHOLD_POINTS:
                log(f"{ev.candidate.label}: {name} stays ({-loss:+.2f} points held at {value:g})")
                continue
            log(f"{ev.candidate.label}: {name} held at its default {value:g} ({-loss:+.2f} points; a "
                f"parameter must be worth {THRESHOLD_POINTS:g})")
            ev.candidate = replace(ev.candidate, free=[fp for fp in ev.candidate.free if fp.key != p.key],
                                   fixed={**ev.candidate.fixed, name: value})
            ev.held_at_default[name] = value
            for e in accepted:
                e.values = {k: values.get(k, v) for k, v in e.values.items() if k != p.key or e is not ev}
            held.append((ev, p, value, s))
            model, full = alt, s
    return model, full, held


# ---- backward pass and final check ----------------------------------------------------------------------
def backward(accepted: list[Evaluation], model, full: float, refit_without: Callable, log=None,
             misses: Callable | None = None, score_on: Callable | None = None):
    """Drop an accepted effect whose removal (the others refitted) costs less than the threshold:
    an early pick can be a stand-in for effects named later. ``full``: the score of ``model``;
    ``refit_without(model, ev, rest)`` -> (model without ``ev``, the rest refitted; its score); for the
    members of a pair named together ``ev`` is the pair's evaluation. ``score_on(model, ev)``: the
    score on the joints ``ev`` acts on, the scale its gain was judged on when it joined (a deadband
    on one of ten joints moves the ten joints' mean by a tenth of what it moves its own); None: the
    removal's cost is taken on ``full``'s scale. ``misses(model)``: whether a
    model would be reported as not explaining the record (:func:`misses_record`); an effect without
    which the model misses the record, where with it it does not, is kept whatever its points (the
    score is a mean over channels: a leak that closes the rest of a chamber-pressure misfit is worth
    little of it, and without it the rest is left unexplained). Returns (model, accepted)."""
    log = log or (lambda msg: None)
    units: list[list[Evaluation]] = []          # a pair named together goes as a unit
    for ev in accepted:
        if ev.pair is not None and units and units[-1][0].pair is ev.pair:
            units[-1].append(ev)
        else:
            units.append([ev])
    for unit in reversed(units):
        rest = [e for e in accepted if not any(e is u for u in unit)]
        what = unit[0].pair or unit[0]          # ``refit_without`` gets the pair's evaluation for a pair
        minus, s = refit_without(model, what, rest)
        drop = full - s if score_on is None else score_on(model, what) - score_on(minus, what)
        if drop < THRESHOLD_POINTS and misses is not None and misses(minus) and not misses(model):
            log(f"backward: kept {what.candidate.label} (removing it costs {drop:.2f} points and leaves the record "
                f"unexplained)")
        elif drop < THRESHOLD_POINTS:
            log(f"backward: dropped {what.candidate.label} (removing it costs {drop:.2f} points)")
            for u in unit + ([what] if what is not unit[0] else []):
                u.reasons.append(f"dropped in the backward pass: removing {'the pair' if len(unit) > 1 else 'it'} "
                                 f"costs only {drop:.2f} points")
            model, accepted, full = minus, rest, s
    return model, accepted


def final_check(chosen: list[Evaluation], model, *, refit: Callable, worth: Callable, remove: Callable, log=None,
                needed: Callable | None = None):
    """Every named effect must still be worth the threshold in the refitted final model.

    ``refit(model, chosen)`` -> a fit (opaque); ``worth(fit, chosen)`` -> points each effect is worth
    in it (the score with it minus without it); ``remove(fit, ev)`` -> the fitted model without
    ``ev`` (for a member of a pair, ``ev`` is the pair's evaluation: both go). The weakest effect under the threshold is dropped and the rest refitted, until all pass.
    ``needed(fit, i)``: whether without the i-th effect (called after ``worth`` on the same fit) the
    model would miss the record while with it it does not; such an effect is kept whatever its
    points, as in :func:`backward`. Returns (chosen, the last fit or None when nothing is left)."""
    log = log or (lambda msg: None)
    chosen = list(chosen)
    fit = None
    while chosen:
        fit = refit(model, chosen)
        w = worth(fit, chosen)
        short = [i for i in range(len(w)) if w[i] < THRESHOLD_POINTS and not (needed is not None and needed(fit, i))]
        if not short:
            break
        k = min(short, key=lambda i: w[i])
        ev = chosen.pop(k)
        ev.reasons.append(f"dropped in the final check: removing it from the refitted model costs only {w[k]:.2f} points")
        log(f"final check: dropped {ev.candidate.label} ({w[k]:.2f} points)")
        if ev.pair is not None:     # a pair was identified together: its other member goes with it
            ev.pair.reasons.append(f"dropped in the final check: removing {ev.candidate.label} from the refitted "
                                   f"model costs only {w[k]:.2f} points")
            for other in [e for e in chosen if e.pair is ev.pair]:
                chosen.remove(other)
                other.reasons.append(f"dropped in the final check with {ev.candidate.label}, named together with it")
        model, fit = remove(fit, ev.pair or ev), None
    return chosen, fit


# ---- ambiguity ------------------------------------------------------------------------------------------
def ambiguous(winner: Evaluation, runner_up: Evaluation) -> bool:
    """A runner-up of another candidate whose gain is within 20 % of the winner's."""
    return runner_up.gain >= AMBIGUITY * winner.gain and runner_up.key != winner.key


def rivalry(winner: Evaluation, round_evals: list[Evaluation], have_pressures: bool,
            acts_on: Callable | None = None) -> dict:
    """The runner-up of the winner's round, whether the choice is ambiguous, and what would decide.

    When it is, ``rivals`` lists every candidate of the round within the margin (the runner-up first,
    then by gain), each with what would decide it from the winner: on a position-only record several
    effects can set the same speeds per volt (a valve asymmetry, an area ratio, a payload and a
    Coulomb friction within 0.02 points of each other), and naming only the runner-up hides that the
    named one is one of four. ``acts_on(candidate)``: the joints a candidate's gain is taken on; a
    candidate on none of the winner's is no rival (a deadband on another joint, whose gain is on
    that joint's score, explains another misfit, not this one). None: every candidate of the round."""
    mine = None if acts_on is None else set(acts_on(winner.candidate))
    others = [e for e in round_evals if e is not winner and (mine is None or mine & set(acts_on(e.candidate)))]
    if not others:
        return {}
    ru = max(others, key=lambda e: e.gain)
    out: dict = {"runner_up": {"effect": ru.candidate.effect, "joint": ru.candidate.joint, "gain": round(ru.gain, 3),
                               "residual_explained_pct": _pct(ru.explained_pct)}}
    if ambiguous(winner, ru):
        out["ambiguous"] = True
        out["decided_by"] = decider(winner.candidate.effect, ru.candidate.effect, have_pressures)
        close, seen = [], set()
        for e in sorted(others, key=lambda e: -e.gain):
            if ambiguous(winner, e) and e.key not in seen:
                seen.add(e.key)
                close.append({"effect": e.candidate.effect, "joint": e.candidate.joint, "gain": round(e.gain, 3),
                              "decided_by": decider(winner.candidate.effect, e.candidate.effect, have_pressures)})
        out["rivals"] = close
    else:
        out["ambiguous"] = False
    return out


# ---- verdict ----------------------------------------------------------------------------------------------
def unexplained_reasons(*, score: float, ceiling: float, angle_fits: dict[str, float], residual_fails: bool,
                        base_score: float | None = None, channel_fits: dict[str, dict[str, float]] | None = None,
                        channel_ceilings: dict[str, dict[str, float]] | None = None,
                        base_channel_fits: dict[str, dict[str, float]] | None = None,
                        named: bool | None = None, disturbance: bool = True) -> list[str]:
    """Why the final model (the extended one, or the baseline when nothing is named) does not
    explain the record; empty when it does.

    * an angle fit below zero on a diagnosed joint: the model is further from the record than its
      mean is; where the angle's ceiling is known, with a misfit of more than FAR_NOISE noises (a
      joint held through the validation part moves there by its noise, and its mean is as good a
      model as any);
    * its score missing the noise ceiling by far (:func:`far`: more than FAR_POINTS below it, and a
      misfit beyond the noise of more than FAR_NOISE noises) while the residual tests fail (the
      misfit is in the data, not in the noise). Named effects that closed most of a runaway
      baseline's distance do not excuse it: a named cause must explain the record, not only beat
      the baseline (``base_score`` only says how much of the distance they closed);
    * one recorded channel (``channel_fits``: angle, velocity, pressure per joint) more than
      missing its own noise ceiling (``channel_ceilings``) by far while the residual tests fail:
      a cause that fits the angle and leaves the chamber pressures as wrong as before has not
      explained the record, even when the mean over channels comes close;
    * the velocity channel missing its noise ceiling by far while the residual tests
      pass: the joint's motion, driven by the command through its inertia, leaves a coloured
      residual where the model misses it; one that large and white is a disturbance on the measured
      position (:mod:`.sensor_disturbance`), which the noise ceiling (white noise on the position)
      does not allow for and no effect explains (``disturbance`` False: not judged). An angle far
      off with a white velocity residual (a level or drift the calibration left) is not this;
    * named effects (``base_channel_fits``: the baseline's channel fits, given when effects are
      named) that leave a chamber pressure more than THRESHOLD_POINTS below its noise ceiling
      after closing less than EXPLAINED_SHARE of the baseline's distance on it. The residual tests
      see the velocity residual only; a cause that fits the motion and leaves much of a pressure
      misfit (a Coulomb friction standing for a Stribeck curve, a leak for a low supply pressure)
      is the closest effect, not the cause;
    * nothing named (``named`` False) while a joint's score (the record's, without channel figures)
      sits more than THRESHOLD_POINTS and WORTH_NOISE noises below its noise ceiling
      (:func:`worth_naming`) and the residual tests fail: the record shows a misfit worth more than any gain that
      counts, and neither the calibration nor a candidate explains it. ``no_significant_discrepancy``
      would say the model matches the record; it does not. ``named`` None: this rule is not applied."""
    why = []
    angle_ceiling = {j: c["angle"] for j, c in (channel_ceilings or {}).items() if "angle" in c}
    below = {j: f for j, f in angle_fits.items()
             if not f >= 0.0 and not misfit_in_noise(f, angle_ceiling.get(j, math.nan)) <= FAR_NOISE}
    if below:
        why.append("angle fit below zero on " + ", ".join(f"{j} ({f:.1f} %)" for j, f in below.items()))
    gap = ceiling - score
    if far(score, ceiling) and residual_fails:
        text = (f"the model's score {score:.1f} is {gap:.1f} points below its noise ceiling {ceiling:.1f} ("
                f"{_noises(score, ceiling)}; {FAR_MARK}) and its residual tests fail")
        if base_score is not None and base_score < score and ceiling > base_score:
            text += (f"; the effects it adds close {100 * (score - base_score) / (ceiling - base_score):.0f} % of the "
                     f"baseline's distance")
        why.append(text)
    elif residual_fails and channel_fits and channel_ceilings:
        off = far_channels(channel_fits, channel_ceilings)
        if off:
            why.append("the model's " + _far_text(off) + f" ({FAR_MARK}) and its residual tests fail")
    elif disturbance and not residual_fails and channel_fits and channel_ceilings:
        off = far_channels(channel_fits, channel_ceilings, WHITE_MISS_CHANNELS)
        if off:
            why.append("the model's " + _far_text(off) + f" ({FAR_MARK}) while its residual tests "
                       "pass: a misfit that large, white and uncorrelated with the command is no motion of the "
                       "joint the model leaves out, but something on the measured position")
    scores = joint_scores(channel_fits, channel_ceilings) if channel_fits and channel_ceilings else {}
    by_joint = bool(scores)
    short = furthest_below({j: fc for j, fc in (scores or {"": (score, ceiling)}).items() if worth_naming(*fc)})
    if not why and named is False and residual_fails and short:
        where = (f"on {short[0]} the model's score {short[2]:.1f} is {short[1]:.1f} points below its noise ceiling "
                 f"{short[3]:.1f}" if by_joint and len(channel_fits) > 1 else
                 f"the model's score {short[2]:.1f} is {short[1]:.1f} points below its noise ceiling {short[3]:.1f}")
        why.append(f"nothing in the bank explains the misfit the residual tests show: {where} ("
                   f"{_noises(short[2], short[3])}), more than the {THRESHOLD_POINTS:g} points a named cause must "
                   f"gain and {WORTH_NOISE:g} noise")
    if base_channel_fits and channel_fits and channel_ceilings:
        for j, fits in channel_fits.items():
            c = channel_ceilings.get(j, {}).get("pressure")
            f, b = fits.get("pressure"), base_channel_fits.get(j, {}).get("pressure")
            if c is None or f is None or b is None:
                continue
            left, before = c - f, c - b
            if far(f, c) and residual_fails:
                continue                    # already unexplained by the rules above
            if left > THRESHOLD_POINTS and not left <= (1.0 - EXPLAINED_SHARE) * before:
                done = f"close {100 * (1.0 - left / before):.0f} %" if before > 0 else "do not close any"
                why.append(f"the named effects {done} of the baseline's pressure misfit on {j} (from {before:.1f} to "
                           f"{left:.1f} points below its noise ceiling {c:.1f}); a cause must close "
                           f"{100 * EXPLAINED_SHARE:.0f} % of a misfit the residual tests do not see")
    return why


def joint_scores(channel_fits: dict[str, dict[str, float]],
                 channel_ceilings: dict[str, dict[str, float]]) -> dict[str, tuple[float, float]]:
    """joint -> (score, ceiling) of each joint whose channels have ceilings: the mean of its channel
    fits against the mean of those channels' ceilings. A misfit on one of ten joints moves their mean
    by a tenth, so the record is judged joint by joint; on one joint this is the record's score
    against its ceiling."""
    out = {}
    for j, fits in channel_fits.items():
        chans = [c for c in fits if c in channel_ceilings.get(j, {})]
        if chans:
            out[j] = (float(np.mean([fits[c] for c in chans])), float(np.mean([channel_ceilings[j][k] for k in chans])))
    return out


def furthest_below(scores: dict[str, tuple[float, float]]) -> tuple[str, float, float, float] | None:
    """(joint, points, score, ceiling) of the joint of ``scores`` furthest below its ceiling (one whose
    gap is not a number first); None for none."""
    best = None
    for j, (f, c) in scores.items():
        if best is None or not c - f <= best[1]:
            best = (j, c - f, f, c)
    return best


def worth_naming(fit: float, ceiling: float) -> bool:
    """Whether a model this far below its noise ceiling leaves a misfit a named cause could gain on:
    more than THRESHOLD_POINTS, and a misfit beyond the noise of more than WORTH_NOISE noises
    (:func:`misfit_in_noise`). A joint homed at the start of a record and held through its
    validation part moves there by its noise alone (a ceiling near 0): two points of that spread
    are a fifth of a noise, what an estimate of the noise a few percent off makes of a perfect model.
    A fit or ceiling that is not a number is worth it."""
    return _short_of(fit, ceiling, THRESHOLD_POINTS, WORTH_NOISE)


def position_misfit(channel_fits: dict[str, dict[str, float]], channel_ceilings: dict[str, dict[str, float]]) -> float:
    """The largest misfit beyond the noise, in noises (:func:`misfit_in_noise`), of the position
    channels (POSITION_CHANNELS) over the joints; 0 where none has a ceiling. The position is what
    every record measures, its noise the sensor's own (second differences); a model that misses it
    by more than the noise moves otherwise than the joint did. Not the other channels: a velocity
    ceiling is an estimate (clean records miss it by up to 4 points), and chamber pressures are
    measured so finely that a model a percent off misses them by hundreds of noises (an oil 15 %
    softer than the spec: 4.3 points, 235 noises)."""
    return max((misfit_in_noise(f, channel_ceilings[j][c]) for j, fits in channel_fits.items()
                for c, f in fits.items() if c in POSITION_CHANNELS and c in channel_ceilings.get(j, {})),
               default=0.0)


def misfit_in_noise(fit: float, ceiling: float) -> float:
    """RMS of a model's misfit beyond the noise, in units of the noise RMS, from its NRMSE fit and the
    channel's noise ceiling (percent). The ceiling is the fit of a perfect model, so
    (100 - fit) / (100 - ceiling) is the residual's norm over the noise's; the residual being the
    misfit plus the noise, uncorrelated, the misfit is sqrt(ratio**2 - 1) noises. 0 at or above the
    ceiling; inf where the ceiling is 100 (no noise) and the fit below it."""
    spread, left = 100.0 - ceiling, 100.0 - fit
    if not left > spread:
        return 0.0 if left <= spread else math.inf
    return math.inf if spread <= 0.0 else math.sqrt((left / spread) ** 2 - 1.0)


def far(fit: float, ceiling: float) -> bool:
    """Whether a fit misses its channel by far: more than FAR_POINTS below the noise ceiling, and a
    misfit beyond the noise of more than FAR_NOISE times the noise. Points are shares of the
    signal's spread; on a channel that barely moves in the validation part (a low ceiling: a joint
    a loop holds) ten points are less than the noise, which no model can be judged by. On a channel
    well above its noise ten points are many noises, and the points decide. A fit or ceiling that is
    not a number counts as far."""
    return _short_of(fit, ceiling, FAR_POINTS, FAR_NOISE)


def _short_of(fit: float, ceiling: float, points: float, noises: float) -> bool:
    """More than ``points`` below the noise ceiling and more than ``noises`` noises of misfit
    (:func:`misfit_in_noise`); a fit or ceiling that is not a number is."""
    return not (ceiling - fit <= points or misfit_in_noise(fit, ceiling) <= noises)


def far_channels(channel_fits: dict[str, dict[str, float]], channel_ceilings: dict[str, dict[str, float]],
                 channels: tuple[str, ...] | None = None) -> list[tuple[str, str, float, float]]:
    """(joint, channel, fit, ceiling) of every channel (of ``channels``, or any) whose fit misses its
    noise ceiling by far (:func:`far`); a fit that is not a number counts as far."""
    return [(j, ch, f, channel_ceilings[j][ch]) for j, fits in channel_fits.items() for ch, f in fits.items()
            if (channels is None or ch in channels) and ch in channel_ceilings.get(j, {})
            and far(f, channel_ceilings[j][ch])]


def _far_text(off: list[tuple[str, str, float, float]]) -> str:
    return "; ".join(f"{ch} fit on {j} {f:.1f} is {c - f:.1f} points below its noise ceiling {c:.1f}, "
                     f"{_noises(f, c)}" for j, ch, f, c in off)


def _noises(fit: float, ceiling: float) -> str:
    m = misfit_in_noise(fit, ceiling)
    return f"a misfit of {m:.1f} noises" if math.isfinite(m) else "a misfit on a channel without noise"


def verdict(named: bool, unexplained: bool) -> str:
    """``unexplained_discrepancy`` overrides a named cause: a cause that leaves the record unexplained
    is not reported as the cause."""
    if unexplained:
        return UNEXPLAINED
    return NAMED if named else NONE


def _pct(v: float):
    return None if not math.isfinite(v) else round(float(v), 1)
