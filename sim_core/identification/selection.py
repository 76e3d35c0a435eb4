"""The decision: fit every candidate, score it on validation data, accept only what the data demands.

Each candidate is fitted by output error on the estimation data together with the calibrated
nominal parameters (and any effects already accepted), then simulated on the validation data. Its
gain is the rise of the joint's decision score (mean NRMSE fit of angle, velocity and recorded
pressures) over the current model. A candidate is accepted when

* gain >= max(2 points, 3 x the noise spread of the gain): the spread is the standard deviation of
  the gain over re-drawn sensor noise of the size measured in the record;
* its BIC on the estimation data improves (a secondary check: coloured output-error residuals make
  BIC prefer extra parameters, so it never decides alone);
* its parameters are identified: none ends on a search bound other than the one where the effect
  vanishes, and at least one differs from "no effect" by more than 3 standard deviations.

The best accepted candidate joins the model (greedy forward selection); the next round refits every
remaining candidate jointly with everything accepted (a large effect masks the others, so first-round
gains are no guide), and stops when nothing passes or when the score is within the threshold of its
noise ceiling; a backward pass then drops any accepted effect whose removal costs less than the
threshold. The runner-up is kept; when its gain is within 20 % of the
winner's the choice is flagged ambiguous with the measurement that would decide.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np

from . import output_error as oe
from .candidates import Candidate
from .metrics import savgol_window
from .parameters import FreeParameter, free_parameter
from .record import Record
from .simulation import Outputs, Runner

THRESHOLD_POINTS = 2.0      # smallest validation gain that counts (research note: 2 points)
NOISE_FACTOR = 3.0          # ... or 3 x the noise spread of the gain, when larger
SIGNIFICANCE = 3.0          # |value - null| / sigma of an identified parameter
AMBIGUITY = 0.8             # runner-up gain above this share of the winner's: ambiguous
MAX_EFFECTS = 3
NOISE_DRAWS = 16
UNCERTAINTY_SHARE = 0.5     # candidates below this share of the threshold skip the uncertainty step
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
    grid: oe.Problem | None = None      # where starting points are ranked (a shorter window)


@dataclass
class Evaluation:
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
    outputs: Outputs | None = None

    @property
    def accepted_ok(self) -> bool:
        return not self.reasons

    def effect_params(self) -> dict[str, float]:
        """The candidate's own parameters (effect keys), by parameter name."""
        return {fp.key.split(".")[-1]: self.values[fp.key] for fp in self.candidate.free}


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


def free_list(spec, cand: Candidate | None, accepted: list[tuple[Candidate, dict]], calib_keys: list[str]) -> list[FreeParameter]:
    free: list[FreeParameter] = list(cand.free) if cand else []
    for c, _ in accepted:
        free += list(c.free)
    free += [free_parameter(spec, k, span=CALIBRATION_SPAN) for k in calib_keys]
    return free


def affected_joints(cand: Candidate, targets: list[str]) -> list[str]:
    return [cand.joint] if cand.joint in targets else list(targets)


def evaluate(st: Setting, cand: Candidate, base_spec, accepted: list[tuple[Candidate, dict]],
             base_out: Outputs, base_cost: float, round_: int = 1) -> Evaluation:
    """Fit ``cand`` (jointly with the accepted effects and the calibration) and score it."""
    s0 = model_with(base_spec, accepted, cand, {})
    free = free_list(s0, cand, accepted, st.calib_keys)
    rest = [fp.get(s0) for fp in free[len(cand.free):]]
    grid = [list(p) + rest for p in cand.grid]
    res = oe.fit(st.est_runner, st.est, s0, free, grid=grid, grid_problem=st.grid, max_sims=st.max_sims,
                 uncertainty=False, tol=1e-3)
    out = st.val_runner.simulate(res.spec, st.val.n)
    if not out.ok and st.val_runner.substep is not None:
        # the fast integrator step was checked on the baseline, not on every fitted candidate: a
        # candidate that diverges there is scored, like the model it is compared with, at the default step
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
    for ch in ("angle", "velocity", "pressure"):
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
    """Apply the acceptance rules; the reasons a candidate fails are kept for the report."""
    significant = 0
    for fp in ev.candidate.free:
        key = fp.key
        v = ev.values[key]
        sig = ev.sigma.get(key, math.inf)
        null = fp.null
        bound = res.at_bound(key) if res.ok else None
        null_side = None
        if null is not None and not math.isnan(null):
            null_side = "lower" if null <= fp.lower + 1e-12 * max(1.0, abs(fp.lower)) else (
                "upper" if null >= fp.upper - 1e-12 * max(1.0, abs(fp.upper)) else None)
        ref = 0.0 if null is None or not math.isfinite(null) else null
        t = abs(v - ref) / sig if sig > 0 and math.isfinite(sig) else 0.0
        ev.significance[key] = t
        if bound is not None:
            ev.bounds[key] = bound
            if bound == null_side:
                continue                      # at the value where the effect vanishes: absent
            ev.reasons.append(f"{key.split('.')[-1]} at its {bound} search bound")
            continue
        if t > SIGNIFICANCE:
            significant += 1
    if not significant and not any("search bound" in r for r in ev.reasons):
        ev.reasons.append(f"no parameter differs from 'no effect' by {SIGNIFICANCE:g} sigma")
    if not math.isfinite(ev.gain):
        ev.reasons.append("the fitted model cannot be simulated on the validation data (the state diverged)")
        return
    need = max(THRESHOLD_POINTS, NOISE_FACTOR * ev.spread)
    if ev.gain < need:
        ev.reasons.append(f"validation gain {ev.gain:.2f} below {need:.2f} points")
    if not ev.bic_delta < 0:
        ev.reasons.append(f"BIC does not improve ({ev.bic_delta:+.1f})")


def noise_spread(st: Setting, out_c: Outputs, out_0: Outputs, joints: list[str], draws: int = NOISE_DRAWS) -> float:
    """Standard deviation of the validation gain over re-drawn sensor noise (seeded, reproducible)."""
    rng = np.random.default_rng(12345)
    val = st.val
    gains = []
    for _ in range(draws):
        angles = {}
        pressures = {}
        for j in val.joints:
            y = out_c.angles[j][: val.n]
            angles[j] = y + rng.normal(0.0, st.noise.get(j, 0.0), y.size)
            if j in out_c.pressures and (j, "p_a") in val.meas:
                sp = st.pressure_noise.get(j, 0.0)
                pa, pb = out_c.pressures[j]
                pressures[j] = (pa[: val.n] + rng.normal(0.0, sp, val.n), pb[: val.n] + rng.normal(0.0, sp, val.n))
        rec = Record("noise", val.rec.time[: val.n], val.rec.U[: val.n], angles, pressures, val.rec.joint_names,
                     val.rec.excited, val.rec.initial_pose)
        prob = oe.Problem(rec, val.joints, n=val.n, start=val.start, pressures=val.use_pressures)
        fc, f0 = prob.fits(out_c), prob.fits(out_0)
        gains.append(np.mean([fc[j]["score"] - f0[j]["score"] for j in joints]))
    return float(np.std(gains))


def score_ceiling(st: Setting, joints: list[str]) -> float:
    """Best decision score a perfect model could reach on the validation data, given the noise."""
    from scipy.signal import savgol_coeffs

    val = st.val
    w = savgol_window(val.rec.rate)
    kv = float(np.linalg.norm(savgol_coeffs(w, 2, deriv=1, delta=val.rec.dt)))
    vals = []
    for j in joints:
        chans = []
        for ch, sig in (("angle", st.noise.get(j, 0.0)), ("velocity", st.noise.get(j, 0.0) * kv)):
            y = val.meas[(j, ch)]
            den = float(np.linalg.norm(y - y.mean())) or 1.0
            chans.append(100.0 * (1.0 - sig * math.sqrt(y.size) / den))
        if (j, "p_a") in val.meas:
            pc = []
            for ch in ("p_a", "p_b"):
                y = val.meas[(j, ch)]
                den = float(np.linalg.norm(y - y.mean())) or 1.0
                pc.append(100.0 * (1.0 - st.pressure_noise.get(j, 0.0) * math.sqrt(y.size) / den))
            chans.append(float(np.mean(pc)))
        vals.append(float(np.mean(chans)))
    return float(np.mean(vals))


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
    bar = _progress(len(cands), f"round {round_}: fitting {len(cands)} candidates", progress)
    if backend is not None:
        for o in backend.map(_task, shared, order):
            if o.error is not None:
                raise o.error
            i, ev = o.value
            results[i] = ev
            bar.set_postfix_str(f"{ev.candidate.label} {ev.gain:+.1f}", refresh=False)
            bar.update(1)
    elif workers <= 1 or len(cands) <= 1:
        _init_worker(shared)
        for i in order:
            _, ev = _work(i)
            results[i] = ev
            bar.update(1)
    else:
        methods = multiprocessing.get_all_start_methods()
        ctx = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                                 initargs=(shared,)) as pool:
            futures = [pool.submit(_work, i) for i in order]
            for f in as_completed(futures):
                i, ev = f.result()
                results[i] = ev
                bar.set_postfix_str(f"{ev.candidate.label} {ev.gain:+.1f}", refresh=False)
                bar.update(1)
    bar.close()
    return [r for r in results if r is not None]


def _progress(total: int, desc: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="fit", disable=not enabled, file=sys.stderr, leave=False)


# ---- greedy forward selection ---------------------------------------------------------------------
@dataclass
class Selection:
    accepted: list[Evaluation]
    rounds: list[list[Evaluation]]
    model: object                       # the extended model spec (fast numerics)
    values: dict[str, float]
    stopped: str
    ceiling: float


def select(st: Setting, cands: list[Candidate], base_spec, *, workers: int = 0, progress: bool = True,
           max_effects: int = MAX_EFFECTS, log=None, backend=None) -> Selection:
    log = log or (lambda msg: None)
    accepted: list[tuple[Candidate, dict]] = []
    accepted_evals: list[Evaluation] = []
    rounds: list[list[Evaluation]] = []
    model = base_spec
    values: dict[str, float] = {}
    pool = list(cands)
    ceiling = score_ceiling(st, st.val.joints)
    stopped = "no candidate passed"
    for r in range(1, max_effects + 1):
        base_out = st.val_runner.simulate(model, st.val.n)
        base_cost = float(np.sum(st.est.residuals(st.est_runner.simulate(model, st.est.n)) ** 2))
        score = float(np.mean([v["score"] for v in st.val.fits(base_out).values()]))
        if r > 1 and ceiling - score < THRESHOLD_POINTS:
            stopped = f"score {score:.1f} within {THRESHOLD_POINTS:g} points of its noise ceiling {ceiling:.1f}"
            break
        if not pool:
            stopped = "no candidates left"
            break
        evals = evaluate_all(st, pool, model, accepted, base_out, base_cost, r, workers=workers, progress=progress,
                             backend=backend)
        rounds.append(evals)
        ok = [e for e in evals if e.accepted_ok]
        if not ok:
            stopped = "no candidate passed" if r == 1 else "no further candidate passed"
            break
        best = max(ok, key=lambda e: e.gain)
        log(f"round {r}: accepted {best.candidate.label} ({best.gain:+.2f} points)")
        accepted.append((best.candidate, best.effect_params()))
        accepted_evals.append(best)
        values.update(best.values)
        model = model_with(model, [], best.candidate, best.values)
        done = {(c.effect, c.joint) for c, _ in accepted}
        # a large effect masks the others: every remaining candidate gets another chance
        pool = [c for c in cands if (c.effect, c.joint) not in done]
    else:
        stopped = f"reached {max_effects} effects"
    if len(accepted) >= 2:
        model, accepted, accepted_evals = backward(st, base_spec, model, accepted, accepted_evals, log)
        values = {}
        for ev in accepted_evals:
            values.update(ev.values)
    return Selection(accepted_evals, rounds, model, values, stopped, ceiling)


def without(base_spec, model, cand: Candidate):
    """``model`` without ``cand``: switched off, or back to the nominal values if the base had it."""
    s = model.copy()
    nominal = [e for e in base_spec.effects if e.name == cand.effect and e.joint == cand.joint]
    if nominal:
        s.enable_effect(cand.effect, cand.joint, **nominal[0].params)
    else:
        s.disable_effect(cand.effect, cand.joint)
    return s


def backward(st: Setting, base_spec, model, accepted, evals, log):
    """Drop an accepted effect whose removal (the others refitted) costs less than the threshold:
    an early pick can be a stand-in for effects named later."""
    score = lambda out: float(np.mean([v["score"] for v in st.val.fits(out).values()]))
    full = score(st.val_runner.simulate(model, st.val.n))
    for i in reversed(range(len(accepted))):
        cand = accepted[i][0]
        rest = accepted[:i] + accepted[i + 1:]
        minus = without(base_spec, model, cand)
        free = free_list(minus, None, rest, st.calib_keys)
        res = oe.fit(st.est_runner, st.est, minus, free, max_sims=st.max_sims, uncertainty=False, tol=1e-3)
        drop = full - score(st.val_runner.simulate(res.spec, st.val.n))
        if drop < THRESHOLD_POINTS:
            log(f"backward: dropped {cand.label} (removing it costs {drop:.2f} points)")
            evals[i].reasons.append(f"dropped in the backward pass: removing it costs only {drop:.2f} points")
            model = res.spec
            accepted, evals = rest, evals[:i] + evals[i + 1:]
            full = score(st.val_runner.simulate(model, st.val.n))
    return model, accepted, evals
