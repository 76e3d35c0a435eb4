"""The decision: fit every candidate, score it on validation data, accept only what the data demands.

Each candidate is fitted by output error on the estimation data together with the calibrated
nominal parameters (and any effects already accepted), then simulated on the validation data. Its
gain is the rise of the joint's decision score (mean NRMSE fit of angle, velocity, recorded
pressures and, on a closed-loop record, the angle restarted from the record: closed_loop.py) over the
current model. A candidate is accepted when

* gain >= max(2 points, 3 x the noise spread of the gain): the spread is the standard deviation of
  the gain over re-drawn sensor noise of the size measured in the record;
* its BIC on the estimation data improves (a secondary check: coloured output-error residuals make
  BIC prefer extra parameters, so it never decides alone);
* its parameters are identified: none ends on a search bound other than the one where the effect
  vanishes, and at least one differs from "no effect" by more than 3 standard deviations.

The best accepted candidate joins the model (greedy forward selection) and the model's own
parameters are refitted as the candidates will refit them; the next round refits every
remaining candidate jointly with everything accepted (a large effect masks the others, so first-round
gains are no guide), and stops when nothing passes or when the score is within the threshold of its
noise ceiling; a backward pass then drops any accepted effect whose removal costs less than the
threshold, and an exchange pass refits each earlier pick against its round's strongest rivals with
the later effects in the model, and a stand-in pass frees in each named effect's place the held
nominal parameter that shares its signature (heavier links for a payload). The rules themselves are
pure functions in decision.py; this module supplies the simulator-based steps they call (fit and
score a candidate, score a model, refit without an effect).
"""

from __future__ import annotations

import math
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from . import output_error as oe
from . import step_timing
from .candidates import Candidate, Pair
from .decision import (AMBIGUITY, MAX_EFFECTS, MAX_PAIRS, NOISE_FACTOR, SIGNIFICANCE, THRESHOLD_POINTS, Evaluation,
                       backward as _backward, exchange, forward, judge, mean_score, member_evaluations, misses_record,
                       pairs_after_a_drop, position_misfit, restart, score_over, simpler_parameters, stand_in)
from .metrics import savgol_window
from .parameters import FreeParameter, declared, free_parameter
from .progress import RoundProgress
from .side_by_side import SideBySide
from .simulation import Outputs, Runner

__all__ = ["AMBIGUITY", "MAX_EFFECTS", "MAX_PAIRS", "NOISE_FACTOR", "SIGNIFICANCE", "THRESHOLD_POINTS", "Evaluation", "Selection",
           "Setting", "channel_ceilings", "evaluate", "select", "without", "model_with", "free_list", "affected_joints",
           "pair_candidate"]

NOISE_DRAWS = 16
UNCERTAINTY_SHARE = 0.5     # candidates below this share of the threshold skip the uncertainty step
FIT_ITERATIONS = 20         # least-squares iterations a fit may take after ranking its starts (a guard: fits stop on
                            # their tolerance)
GRID_SHARE = 0.5            # starting points are ranked on the first half of the estimation data
CALIBRATION_SPAN = 3.0      # a candidate may move the calibrated flow gains within x/÷ 3


@dataclass
class Setting:
    """Everything a candidate evaluation needs (shared with the worker processes)."""

    est_runner: Runner
    est: oe.Problem
    val_runner: Runner
    val: oe.Problem
    calib_keys: list[str]
    noise: dict[str, float]             # angle noise per joint (rad)
    pressure_noise: dict[str, float]    # pressure noise per joint (Pa)
    max_sims: int = 45
    fit_iterations: int = FIT_ITERATIONS
    grid: oe.Problem | None = None      # where starting points are ranked (a shorter window)
    # the spec's estimated parameters (a rig's nuisances) among calib_keys: refitted within the
    # calibration's own ranges, and started also from their values before calibration (with several
    # of them free the calibration can absorb an effect and leave its candidate no way back)
    ranges: dict[str, FreeParameter] = field(default_factory=dict)
    uncalibrated: dict[str, float] = field(default_factory=dict)
    # (joint, channel) -> sum of squares the replay's unknown step instants alone put between a perfect
    # model and the record (step_timing.misfit, its 90th percentile over draws; a period-mean replay),
    # beside the noise's
    replay_misfit: dict[tuple[str, str], float] = field(default_factory=dict)

    def budget(self, n_free: int, n_starts: int = 0, fits: int = 1) -> int:
        """Simulations one fit may spend: ``max_sims``, or what ranking ``n_starts`` starting points
        and ``fit_iterations`` forward-difference iterations of ``n_free`` parameters from each of
        ``fits`` starts take, whichever is more. A fixed budget starves the fits with many free
        parameters: a two-parameter effect beside a rig's three calibrated nuisances, ranked from 15
        starts, had three iterations left and stopped a decade short of the leak it was fitting (with
        8 it stopped at a third of it, and a masked pair stood in). The fits stop on their tolerance
        (that one after 13 iterations); ``fit_iterations`` only keeps a fit that does not converge
        from running on."""
        return max(self.max_sims, n_starts + 1 + fits * self.fit_iterations * (n_free + 1))

    def before_calibration(self, free: list[FreeParameter], values: list[float]) -> list[float]:
        """``values`` (of ``free``, in order) with the spec's estimated parameters at their values
        before calibration: the second start of every refit of the calibrated parameters."""
        return [self.uncalibrated.get(fp.key, v) for fp, v in zip(free, values)]


def model_with(base_spec, accepted: list[tuple[Candidate, dict]], cand: Candidate | None, values: dict[str, float]):
    """``base_spec`` with the accepted candidates and ``cand`` switched on and ``values`` applied."""
    s = base_spec.copy()
    for c, _ in accepted:
        if not any(e.name == c.effect and e.joint == c.joint for e in s.effects):
            s = c.prepare(s)
    if cand is not None:
        s = cand.prepare(s)
    for key, v in values.items():
        _param(s, key).apply(s, v)
    return s


def _param(spec, key: str) -> FreeParameter:
    return FreeParameter(key, -math.inf, math.inf)


def free_list(spec, cand: Candidate | None, accepted: list[tuple[Candidate, dict]], calib_keys: list[str],
              ranges: dict[str, FreeParameter] | None = None, on: list[str] | None = None) -> list[FreeParameter]:
    """The candidate's, the accepted effects' and the calibration's parameters; a calibration key
    in ``ranges`` keeps that range (the spec's estimated range), the others may move x/÷ 3. ``on``:
    only the accepted effects and calibrated parameters of these joints, or of no one joint, beside
    the candidate's own (None: all)."""
    free: list[FreeParameter] = list(cand.free) if cand else []
    for c, _ in accepted:
        if on is None or c.joint is None or c.joint in on:
            free += list(c.free)
    have = {fp.key for fp in free}
    ranges = ranges or {}
    free += [replace(ranges[k]) if k in ranges else free_parameter(spec, k, span=CALIBRATION_SPAN)
             for k in calib_keys if k not in have and (on is None or key_joint(k) in (None, *on))]
    return free


def key_joint(key: str) -> str | None:
    """The joint a parameter key belongs to (``joints.<joint>.<...>``, ``effects.<effect>.<joint>.<p>``),
    or None for one of the robot as a whole (the supply, the links, a global effect's)."""
    parts = key.split(".")
    if parts[0] == "joints" and len(parts) > 2:
        return parts[1]
    if parts[0] == "effects" and len(parts) == 4:
        return parts[2]
    return None


def affected_joints(cand: Candidate, targets: list[str]) -> list[str]:
    members = getattr(cand, "members", None)
    if members is not None and all(m.joint in targets for m in members):
        return list(dict.fromkeys(m.joint for m in members))
    return [cand.joint] if cand.joint in targets else list(targets)


def evaluate(st: Setting, cand: Candidate, base_spec, accepted: list[tuple[Candidate, dict]],
             base_out: Outputs, base_cost: float, round_: int = 1) -> Evaluation:
    """Fit ``cand`` (jointly with the accepted effects and the calibration) and score it. Beside
    accepted effects a new candidate whose null ranks first is fitted from its best grid point too:
    the accepted effects were fitted without it and absorbed what they could of it, so the null
    ranks above starts that hold them there, and a fit started at a null whose slope vanishes (a
    leak's, a deadband's) stays there. In the first round the null alone is fitted where it ranks
    first: the ranking profiles the calibrated flow gains for every start, so there the grid
    explains nothing better (starting every candidate of a clean record from its grid instead cost
    39 % more simulations)."""
    s0 = model_with(base_spec, accepted, cand, {})
    # a candidate on some joints of several refits what acts on those: the other joints' effects and
    # calibration stay where the model has them (each joint has its own valve and actuator; refitting
    # all of them made every candidate of a ten-joint record a fit of 30 parameters)
    on = affected_joints(cand, st.val.joints)
    free = free_list(s0, cand, accepted, st.calib_keys, st.ranges, on=None if set(on) >= set(st.val.joints) else on)
    rest = [fp.get(s0) for fp in free[len(cand.free):]]
    grid = [list(p) + rest for p in cand.grid]
    uncal = st.before_calibration(free[len(cand.free):], rest)
    second = None
    if uncal != rest:
        # fitted from the best of these too, whatever the ranking says (oe.fit, second_family)
        second = len(grid)
        grid += [list(p) + uncal for p in (cand.grid or [[fp.get(s0) for fp in cand.free]])]
    res = oe.fit(st.est_runner, st.est, s0, free, grid=grid, grid_problem=st.grid,
                 max_sims=st.budget(len(free), len(grid), fits=1 if second is None else 2), uncertainty=False,
                 tol=1e-3, grid_start_too=bool(accepted) and not cand.existing, second_family=second)
    out = st.val_runner.simulate(res.spec, st.val.n, resume=res.outputs)
    if (not out.ok or not base_out.ok) and st.val_runner.substep is not None:
        # the fast integrator step was checked on the calibrated baseline, not on every fitted candidate
        # or recalibrated model: where either diverges there, both are scored at the default step
        default = Runner(st.val_runner.rec)
        out = default.simulate(res.spec, st.val.n)
        base_out = default.simulate(base_spec, st.val.n)
    fits = st.val.fits(out)
    base_fits = st.val.fits(base_out)
    joints = affected_joints(cand, st.val.joints)
    gain = float(np.mean([fits[j]["score"] - base_fits[j]["score"] for j in joints]))
    if gain >= UNCERTAINTY_SHARE * THRESHOLD_POINTS:     # only a candidate that may pass needs its sigmas
        oe.add_uncertainty(res, st.est_runner, st.est)
    ev = Evaluation(cand, res.values, res.sigma, res.ci95, res.cost, fits, sims=res.sims, round=round_, outputs=out)
    ev.gain = gain
    ev.base_score = float(np.mean([base_fits[j]["score"] for j in joints]))
    for ch in ("angle", "restarted", "velocity", "pressure"):
        vals = [fits[j][ch] - base_fits[j][ch] for j in joints if ch in fits[j]]
        if vals:
            ev.gain_channels[ch] = float(np.mean(vals))
    n = st.est.n - st.est.start
    k = len(cand.free)
    if res.ok and base_cost > 0 and res.cost > 0:
        ev.bic_delta = float(n * math.log(res.cost / base_cost) + k * math.log(n))
    else:
        ev.bic_delta = math.inf
    ev.spread = noise_spread(st, out, base_out, joints) if out.ok and base_out.ok else math.inf
    _judge(ev, res)
    return ev


def _judge(ev: Evaluation, res: oe.FitResult) -> None:
    """The acceptance rules (decision.judge) with the fit's parameters on a search bound."""
    bounds = {}
    if res.ok:
        for fp in ev.candidate.free:
            side = res.at_bound(fp.key)
            if side is not None:
                bounds[fp.key] = side
    judge(ev, bounds)


def noise_spread(st: Setting, out_c: Outputs, out_0: Outputs, joints: list[str], draws: int = NOISE_DRAWS) -> float:
    """Standard deviation of the validation gain over re-drawn sensor noise (seeded, reproducible)."""
    rng = np.random.default_rng(12345)
    val = st.val
    sim_c, sim_0 = val.simulated(out_c), val.simulated(out_0)    # the same channels in every draw
    gains = []
    for _ in range(draws):
        prob = val.redrawn(out_c, st.noise, st.pressure_noise, rng)
        fc, f0 = prob.fits_of(sim_c), prob.fits_of(sim_0)
        gains.append(np.mean([fc[j]["score"] - f0[j]["score"] for j in joints]))
    return float(np.std(gains))


def joint_ceilings(ceilings: dict[str, dict[str, float]]) -> dict[str, float]:
    """Per joint, the best decision score a perfect model could reach: the mean of its channels'
    ceilings (:func:`channel_ceilings`)."""
    return {j: float(np.mean(list(ch.values()))) for j, ch in ceilings.items()}


def score_ceiling(ceilings: dict[str, dict[str, float]]) -> float:
    """Best decision score a perfect model could reach on the validation data, given the noise: the
    mean over joints of :func:`joint_ceilings`."""
    return float(np.mean(list(joint_ceilings(ceilings).values())))


def channel_ceilings(st: Setting, joints: list[str]) -> dict[str, dict[str, float]]:
    """Per joint, the best NRMSE fit (percent) a perfect model could reach on each validation channel
    (angle, velocity and, when recorded, the chambers' pressures), given the noise and, on a
    period-mean replay, the steps' unknown instants (``st.replay_misfit``)."""
    val = st.val
    out = noise_ceilings(val, joints, st.noise, st.pressure_noise)
    for j, chans in out.items():
        for ch in chans:
            extra = st.replay_misfit.get((j, ch))
            if extra:
                chans[ch] = step_timing.ceiling(chans[ch], val.meas[(j, "angle" if ch == "restarted" else ch)], extra)
    return out


def noise_ceilings(prob: oe.Problem, joints: list[str], noise: dict[str, float],
                   pressure_noise: dict[str, float]) -> dict[str, dict[str, float]]:
    """Per joint, the best NRMSE fit (percent) a perfect model could reach on each of ``prob``'s
    channels given the noise alone (``noise``: angle, rad; ``pressure_noise``: Pa, per joint): the
    noise's norm against the channel's spread over the problem's window."""
    from scipy.signal import savgol_coeffs

    w = savgol_window(prob.rec.rate)
    kv = float(np.linalg.norm(savgol_coeffs(w, 2, deriv=1, delta=prob.rec.dt)))
    out = {}
    for j in joints:
        chans = {}
        for ch, sig in (("angle", noise.get(j, 0.0)), ("velocity", noise.get(j, 0.0) * kv)):
            y = prob.meas[(j, ch)]
            den = float(np.linalg.norm(y - y.mean())) or 1.0
            chans[ch] = 100.0 * (1.0 - sig * math.sqrt(y.size) / den)
        if prob.restart:
            chans["restarted"] = chans["angle"]
        if (j, "p_a") in prob.meas:
            pc = []
            for ch in ("p_a", "p_b"):
                y = prob.meas[(j, ch)]
                den = float(np.linalg.norm(y - y.mean())) or 1.0
                pc.append(100.0 * (1.0 - pressure_noise.get(j, 0.0) * math.sqrt(y.size) / den))
            chans["pressure"] = float(np.mean(pc))
        out[j] = chans
    return out


# ---- parallel evaluation --------------------------------------------------------------------------
_SHARED: dict = {}


def _init_worker(shared):
    single_blas_thread()
    _SHARED.clear()
    _SHARED.update(shared)


_LIMITS = []


def single_blas_thread() -> None:
    """One BLAS thread per process: OpenBLAS threads spin after every small least-squares call and
    take the cores the other candidate fits need (measured: no parallel speed-up without this)."""
    from threadpoolctl import threadpool_limits

    _LIMITS.append(threadpool_limits(limits=1, user_api="blas"))


def _work(index: int):
    sh = _SHARED
    cand = sh["candidates"][index]
    ev = evaluate(sh["setting"], cand, sh["base_spec"], sh["accepted"], sh["base_out"], sh["base_cost"], sh["round"])
    return index, ev


def _task(shared, index: int):
    """One candidate fit as a backend's task (``shared`` arrives once per round and worker)."""
    if not _LIMITS:
        single_blas_thread()
    _SHARED.clear()
    _SHARED.update(shared)
    return _work(index)


def evaluate_all(st: Setting, cands: list[Candidate], base_spec, accepted, base_out, base_cost, round_: int,
                 workers: int = 0, progress: bool = True, backend=None) -> list[Evaluation]:
    """Evaluate candidates in parallel processes (forked: the compiled kernel is inherited), or as
    tasks of ``backend`` (:mod:`sim_core.backends`, e.g. Ray) when one is given."""
    shared = {"setting": st, "candidates": cands, "base_spec": base_spec, "accepted": accepted,
              "base_out": base_out, "base_cost": base_cost, "round": round_}
    workers = workers or min(len(cands), os.cpu_count() or 1)
    order = sorted(range(len(cands)), key=lambda i: -len(cands[i].free) * (1 + len(cands[i].grid)))
    results: list[Evaluation | None] = [None] * len(cands)
    bar = RoundProgress(len(cands), f"round {round_}: fitting {len(cands)} candidates", progress)
    if backend is not None:
        for o in backend.map(_task, shared, order):
            if o.error is not None:
                raise o.error
            i, ev = o.value
            results[i] = ev
            bar.done(ev)
    elif workers <= 1 or len(cands) <= 1:
        _init_worker(shared)
        for i in order:
            _, ev = _work(i)
            results[i] = ev
            bar.done(ev)
    else:
        methods = multiprocessing.get_all_start_methods()
        ctx = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                                 initargs=(shared,)) as pool:
            futures = [pool.submit(_work, i) for i in order]
            for f in as_completed(futures):
                i, ev = f.result()
                results[i] = ev
                bar.done(ev)
    bar.close()
    return [r for r in results if r is not None]


# ---- masked pairs ----------------------------------------------------------------------------------
def pair_candidate(a: Evaluation, b: Evaluation) -> Pair:
    """Two single evaluations as a Pair to fit jointly. Starting points: both at their single fits,
    then each member's own grid with the other at its single fit (a member absorbed alone sits near
    "no effect", its partner's grid finds where the two separate)."""
    va = [a.values[fp.key] for fp in a.candidate.free]
    vb = [b.values[fp.key] for fp in b.candidate.free]
    grid = [va + vb] + [list(g) + vb for g in a.candidate.grid] + [va + list(g) for g in b.candidate.grid]
    alone = {e.candidate.label: {"gain": round(e.gain, 3), "rejected_because": list(e.reasons)} for e in (a, b)}
    return Pair((a.candidate, b.candidate), grid, alone)


# ---- greedy forward selection ---------------------------------------------------------------------
@dataclass
class Selection:
    accepted: list[Evaluation]
    rounds: list[list[Evaluation]]
    model: object                       # the extended model spec (fast numerics)
    values: dict[str, float]
    stopped: str
    ceiling: float
    pairs: list[list[Evaluation]] = field(default_factory=list)    # the pair fits of each pair search
    # (kept, dropped) after the final check -> (accepted, fast model) with a pair that passes, or None
    resume: Callable | None = None
    # the stand-in pass's replacements: (the effect's evaluation, its stand-in, the value it took,
    # the score with the stand-in, the score with the effect)
    stand_ins: list[tuple] = field(default_factory=list)
    channel_ceilings: dict[str, dict[str, float]] = field(default_factory=dict)   # joint -> channel -> ceiling


def effect_limit(joints: list[str]) -> int:
    """The most effects a diagnosis names: ``MAX_EFFECTS`` per diagnosed joint. Each joint has its own
    valve, actuator and sensor, so a robot whose every valve has the same overlap carries one
    deadband per joint; a limit for the whole record would name three of ten and leave the record
    unexplained."""
    return MAX_EFFECTS * max(1, len(joints))


def select(st: Setting, cands: list[Candidate], base_spec, *, workers: int = 0, progress: bool = True,
           max_effects: int | None = None, log=None, backend=None, recalibrate=None, misfit=None,
           stand_ins: dict[str, list[FreeParameter]] | None = None, checkpoint: Callable | None = None) -> Selection:
    """Greedy forward selection, the masked-pair search, the backward and the exchange pass
    (decision.forward, decision.backward, decision.exchange) with the simulator-based steps: a round
    of candidate fits, pair fits, the validation score, a refit without one effect.
    ``max_effects``: the most effects named (None: :func:`effect_limit` of the validated joints).
    ``recalibrate(model, ev, score)``: the model once ``ev``'s effect is in it, its calibration redone (it may
    change ``st.calib_keys`` in place; ``score(model)`` is the validation score, to judge the redone one
    by); None: the model as extended. ``misfit(validation outputs)``: whether the model's residual tests fail (the
    condition for the pair search); None: no pair search. ``stand_ins``: effect name -> the held
    nominal parameters it must beat (calibration.Plan.stand_ins; decision.stand_in), freed in its place
    after the other passes; one that takes the place joins ``st.calib_keys``. ``checkpoint()``: a
    callable that puts the caller's state that ``recalibrate`` changes back as it was at the call
    (decision.restart runs forward selection again from other first picks)."""
    log = log or (lambda msg: None)
    if max_effects is None:
        max_effects = effect_limit(st.val.joints)
    ceilings = channel_ceilings(st, st.val.joints)
    ceiling = score_ceiling(ceilings)
    base = _Baseline(st)
    if recalibrate is not None:
        recalibrate = partial(recalibrate, score=base.score)

    def evaluate_round(pool, model, accepted, r):
        base_out, base_cost = base.outputs(model), base.cost(model)
        return evaluate_all(st, pool, model, accepted, base_out, base_cost, r, workers=workers, progress=progress,
                            backend=backend)

    def evaluate_pairs(pairs, model, accepted, r):
        log(f"round {r}: no single candidate passed; fitting {len(pairs)} pairs jointly")
        return evaluate_round([pair_candidate(a, b) for a, b in pairs], model, accepted, r)

    added: list[tuple[Candidate, dict]] = []     # what forward selection put into the model so far
    side = SideBySide(workers if backend is None else 1)

    def extend(model, ev):
        added.append((ev.candidate, {}))
        extended = _extend(model, ev, recalibrate)
        polished, scores = _polished(st, extended, added, base, side)
        if scores is not None:
            log(f"refitted the model with {ev.candidate.label}: validation score {scores[0]:.2f} -> {scores[1]:.2f}")
        return polished

    def snapshot():
        outer = checkpoint() if checkpoint is not None else None
        saved_added, saved_keys = list(added), list(st.calib_keys)

        def back():
            if outer is not None:
                outer()
            added[:] = saved_added
            st.calib_keys[:] = saved_keys
        return back

    model_misfit = None if misfit is None else (lambda model: misfit(base.outputs(model)))

    base_fits: list[dict] = []        # the baseline's validation fits, once a path is judged

    def baseline_fits():
        if not base_fits:
            base_fits.append(st.val.fits(base.outputs(base_spec)))
        return base_fits[0]

    def misses(m):
        return misses_record(base.fits(m), ceiling, ceilings, model_misfit(m), baseline_fits())

    def explains(ev):
        """Whether the model with ``ev`` (its validation outputs) passes the residual tests and does
        not miss the record."""
        out = ev.outputs
        if out is None or not out.ok or misfit(out):
            return False
        return not misses_record(ev.fits, ceiling, ceilings, False, baseline_fits())

    per_joint = joint_ceilings(ceilings)

    def short_of_ceiling(m):
        fits = base.fits(m)
        return max(per_joint[j] - fits[j]["score"] for j in per_joint)

    def acts_on(ev):
        return affected_joints(ev.candidate, st.val.joints)

    def score_on(model, ev):
        """The validation score on the joints ``ev`` acts on: the scale its gain is taken on."""
        return score_over(base.fits(model), acts_on(ev))

    def gap_on(model, ev):
        return float(np.mean([per_joint[j] for j in acts_on(ev)])) - score_on(model, ev)

    def run(first=None):
        return forward(cands, base_spec, evaluate_round=evaluate_round, extend=extend,
                       score=base.score, ceiling=ceiling, max_effects=max_effects, log=log,
                       evaluate_pairs=None if misfit is None else evaluate_pairs, misfit=model_misfit, first=first,
                       explains=None if misfit is None else explains, short_of_ceiling=short_of_ceiling,
                       gap_on=gap_on, position_noises=lambda m: position_misfit(base.fits(m), ceilings))

    try:
        to_start = snapshot()
        greedy = run()
        fw = restart(greedy, rerun=lambda ev: run((greedy.rounds[0], ev)), score=base.score,
                     misses=None if misfit is None else misses,
                     to_start=to_start, checkpoint=snapshot, log=log)
    finally:
        side.close()
    model, accepted = fw.model, fw.accepted
    rounds, stopped = list(fw.rounds), fw.stopped
    if len(accepted) >= 2:
        refits: dict[tuple[int, int], tuple] = {}

        def refit_without(model, ev, rest):
            # the backward pass and the exchange pass ask for the same refits: each is fitted once
            hit = refits.get((id(model), id(ev)))
            if hit is not None and hit[0] is model and hit[1] is ev:
                return hit[2]
            res = base.fitted(_refit_rest(st, base_spec, model, ev, rest))
            refits[(id(model), id(ev))] = (model, ev, (res.spec, base.score(res.spec)))
            return refits[(id(model), id(ev))][2]

        def scale(model, ev, rival):
            """The model's score and the rival's model's, on the joints either acts on."""
            joints = list(dict.fromkeys(acts_on(ev) + acts_on(rival)))
            return score_over(base.fits(model), joints), score_over(rival.fits, joints)

        named = list(accepted)
        model, accepted = _backward(accepted, model, base.score(model), refit_without, log,
                                    misses=None if misfit is None else misses, score_on=score_on)
        dropped = [e for e in named if not any(e is a for a in accepted)]
        if len(accepted) >= 2 or (accepted and dropped):
            before = list(accepted)
            model, accepted, tried = exchange(
                accepted, rounds, model, base.score(model), refit_without=refit_without,
                evaluate=lambda pool, minus, rest, r: evaluate_round(
                    pool, minus, [(e.candidate, e.effect_params()) for e in rest], r),
                score_with=lambda ev: mean_score(ev.fits),
                replace=lambda minus, ev: _extend(minus, ev, recalibrate), score=base.score, log=log, scale=scale,
                dropped=dropped)
            rounds += tried
            swaps = [(old, new) for old, new in zip(before, accepted) if old is not new]
            if swaps:
                stopped += "; " + ", ".join(f"{new.candidate.label} named in place of {old.candidate.label}" for old, new in swaps)
    replaced: list[tuple] = []
    if stand_ins and accepted:
        def refit_instead(model, ev, rest, fp):
            res = base.fitted(_refit_rest(st, base_spec, model, ev, rest, instead=fp))
            return res.spec, base.score(res.spec), float(res.values[fp.key]), res.at_bound(fp.key)

        model, accepted, replaced = stand_in(accepted, model, base.score(model),
                                             stand_ins=lambda ev: stand_ins.get(ev.candidate.effect, []),
                                             refit_instead=refit_instead, log=log, score_on=score_on)
        for ev, fp, value, _, _ in replaced:
            if fp.key not in st.calib_keys:
                st.calib_keys.append(fp.key)
            stopped += f"; {fp.key} calibrated in place of {ev.candidate.label} (= {value:.4g})"
    if accepted:
        def refit_held(model, ev, p, value):
            res = base.fitted(_refit_held(st, model, accepted, ev, p, value))
            if not res.ok:
                return model, -math.inf, {}
            return res.spec, base.score(res.spec), res.values

        model, _, held = simpler_parameters(accepted, model, base.score(model),
                                            default=lambda ev, p: effect_default(base_spec, p),
                                            refit_held=refit_held, log=log, score_on=score_on)
        for ev, p, value, _ in held:
            stopped += f"; {ev.candidate.label}: {p.key.split('.')[-1]} held at its default {value:g}, not worth a parameter"
    values: dict[str, float] = {}
    for ev in accepted:
        values.update(ev.values)
    sel = Selection(accepted, rounds, model, values, stopped, ceiling, fw.pairs, stand_ins=replaced,
                    channel_ceilings=ceilings)

    def resume(kept, dropped):
        """decision.pairs_after_a_drop on the search's model without the dropped effects."""
        reduced = model
        for ev in dropped:
            reduced = without(base_spec, reduced, (ev.pair or ev).candidate)
        pevals, best = pairs_after_a_drop(
            kept, dropped, fw, reduced, evaluate_pairs=None if misfit is None else evaluate_pairs, score=base.score,
            ceiling=ceiling, misfit=None if misfit is None else (lambda m: misfit(base.outputs(m))),
            max_effects=max_effects, log=log, short_of_ceiling=short_of_ceiling)
        if not pevals:
            return None
        sel.pairs.append(pevals)
        labels = ", ".join(e.candidate.label for e in dropped)
        if best is None:
            sel.stopped += f"; the final check dropped {labels}, and none of {len(pevals)} pairs passed"
            return None
        sel.stopped += f"; the final check dropped {labels}, then the pair {best.candidate.label} passed"
        log(f"accepted the pair {best.candidate.label} ({best.gain:+.2f} points) after the final check")
        return list(kept) + member_evaluations(best), _extend(reduced, best, recalibrate)

    sel.resume = resume
    return sel


def _refit_rest(st: Setting, base_spec, model, ev: Evaluation, rest: list[Evaluation],
                instead: FreeParameter | None = None) -> oe.FitResult:
    """``model`` without ``ev``'s effect, the ``rest`` and the calibration refitted (the backward and
    exchange passes); with ``instead`` (a held nominal parameter) freed as well, started at its value
    and x 0.8, x 1.25 (the stand-in pass)."""
    minus = without(base_spec, model, ev.candidate)
    free = free_list(minus, None, [(e.candidate, e.effect_params()) for e in rest], st.calib_keys, st.ranges)
    if instead is None:
        return oe.fit(st.est_runner, st.est, minus, free, max_sims=st.budget(len(free)), uncertainty=False, tol=1e-3)
    free = [f for f in free if f.key != instead.key] + [replace(instead)]
    x0 = [f.get(minus) for f in free]
    grid = [x0[:-1] + [instead.from_x(instead.to_x(x0[-1] * f))] for f in (1.0, 0.8, 1.25)]
    return oe.fit(st.est_runner, st.est, minus, free, grid=grid, grid_problem=st.grid,
                  max_sims=st.budget(len(free), len(grid)), uncertainty=False, tol=1e-3)


def effect_default(spec, p: FreeParameter) -> float | None:
    """The default its effect declares for ``p`` (the typical value), or None."""
    d = declared(spec, p.key).default
    return float(d) if isinstance(d, (int, float)) else None


def _refit_held(st: Setting, model, accepted: list[Evaluation], ev: Evaluation, p: FreeParameter,
                value: float) -> oe.FitResult:
    """``model`` with ``ev``'s parameter ``p`` at ``value`` and the other parameters of the named
    effects and the calibration refitted (simpler_parameters)."""
    held = model.copy()
    p.apply(held, value)
    named = [(replace(e.candidate, free=[fp for fp in e.candidate.free if fp.key != p.key]) if e is ev else e.candidate,
              e.effect_params()) for e in accepted]
    free = free_list(held, None, named, st.calib_keys, st.ranges)
    return oe.fit(st.est_runner, st.est, held, free, max_sims=st.budget(len(free)), uncertainty=False, tol=1e-3)


def _extend(model, ev: Evaluation, recalibrate):
    extended = model_with(model, [], ev.candidate, ev.values)
    return extended if recalibrate is None else recalibrate(extended, ev)


def _polished(st: Setting, model, accepted: list[tuple[Candidate, dict]], base: "_Baseline", side: SideBySide):
    """``model`` with its own parameters (the accepted effects' and the calibration's, every joint's)
    refitted the way each candidate of the next round refits those of its joints: from their values
    and, for a rig's nuisances, from their values before calibration, with the candidates' budget. Without it the next round credits
    every candidate alike with what this refit alone finds (the accepted fit stopped on its budget, or
    the other start holds a better optimum). Kept where it scores higher on the validation data:
    returns the model and (score before, score after), or the model unchanged and None."""
    free = free_list(model, None, accepted, st.calib_keys, st.ranges)
    x0 = [fp.get(model) for fp in free]
    uncal = st.before_calibration(free, x0)
    starts = [x0] + ([uncal] if uncal != x0 else [])
    res = oe.fit(st.est_runner, st.est, model, free, grid=starts, grid_problem=st.grid,
                 max_sims=st.budget(len(free), len(starts), fits=len(starts)), uncertainty=False, tol=1e-3,
                 side=side, second_family=1 if len(starts) > 1 else None)
    if not res.ok or res.spec is None:
        return model, None
    base.fitted(res)
    before, after = base.score(model), base.score(res.spec)
    return (res.spec, (before, after)) if after > before else (model, None)


class _Baseline:
    """The validation outputs, score and estimation cost of the models the search compares (each
    simulated once, the last few kept); a model that a fit returned continues that fit's simulation
    of the estimation window (:meth:`fitted`)."""

    KEEP = 6

    def __init__(self, st: Setting):
        self.st = st
        self._out: dict[int, tuple] = {}
        self._fits: dict[int, tuple] = {}
        self._val_fits: dict[int, tuple] = {}

    def fitted(self, res: oe.FitResult) -> oe.FitResult:
        """Remember ``res.spec``'s estimation-window outputs (the fit's, at its optimum); returns ``res``."""
        if res.spec is not None and res.outputs is not None:
            self._fits[id(res.spec)] = (res.spec, res.outputs)
            _keep_last(self._fits, self.KEEP)
        return res

    def _fit_outputs(self, model) -> Outputs | None:
        hit = self._fits.get(id(model))
        return hit[1] if hit is not None and hit[0] is model else None

    def outputs(self, model) -> Outputs:
        hit = self._out.get(id(model))
        if hit is None or hit[0] is not model:
            hit = (model, self.st.val_runner.simulate(model, self.st.val.n, resume=self._fit_outputs(model)))
            self._out[id(model)] = hit
            _keep_last(self._out, self.KEEP)
        return hit[1]

    def fits(self, model) -> dict:
        """The validation fits of ``model`` (joint -> channel -> fit, with its "score"), each computed once."""
        hit = self._val_fits.get(id(model))
        if hit is None or hit[0] is not model:
            hit = (model, self.st.val.fits(self.outputs(model)))
            self._val_fits[id(model)] = hit
            _keep_last(self._val_fits, self.KEEP)
        return hit[1]

    def score(self, model) -> float:
        return mean_score(self.fits(model))

    def cost(self, model) -> float:
        st = self.st
        out = st.est_runner.simulate(model, st.est.n, resume=self._fit_outputs(model))
        return float(np.sum(st.est.residuals(out) ** 2))


def _keep_last(d: dict, n: int) -> None:
    while len(d) > n:
        del d[next(iter(d))]


def without(base_spec, model, cand: Candidate):
    """``model`` without ``cand`` (a single or a pair): switched off, or back to the nominal values if
    the base had it."""
    if isinstance(cand, Pair):
        for m in cand.members:
            model = without(base_spec, model, m)
        return model
    s = model.copy()
    nominal = [e for e in base_spec.effects if e.name == cand.effect and e.joint == cand.joint]
    if nominal:
        s.enable_effect(cand.effect, cand.joint, **nominal[0].params)
    else:
        s.disable_effect(cand.effect, cand.joint)
    return s
