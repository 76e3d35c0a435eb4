"""The rig changed during the record: calibrated on its later part alone, the model fits that part.

A model the bank extends assumes one rig for the whole record. Real ones change while they are
logged: oil warms up over the first minutes (its viscosity falls several-fold: leaks grow, seals drag
less, a valve passes more at small openings), a pump's compensator or an accumulator lets the supply
sag, a load is picked up half way. The baseline is calibrated on the first part of the record (the estimation window) and
misses the rest, the residual grows towards the end, and no effect of the bank explains it: the
record is unexplained. Which it is cannot be told from the misfit alone (a missing piece of physics
leaves one too), but this can: calibrated again on the validation part by itself, the same model
fits it, with parameters that moved well beyond their uncertainty. A misfit that is the same all
through the record (a friction curve or a mode the model lacks) leaves the parameters where they
were and the misfit where it was.

So the record's later part is taken as a record of its own (from a still moment at the start of
the validation window, so the simulation starts as the rig did), the early calibration is scored on
it, calibrated again on it, and the change is said when

* the new calibration closes at least CLOSED_SHARE of the distance between the early calibration's
  score on that part and its noise ceiling, and
* the early calibration fits its own part (the estimation window) at least as much closer to that
  part's noise ceiling than it fits the later part (at most CLOSED_SHARE of the later part's distance
  is left on its own): a rig that changed is fitted by each part's calibration on that part. An
  effect the bank leaves unnamed that the later part shows more of (a flow limit its steps reach
  more often) also moves the recalibrated parameters, but the early part's misfit shows it there too;
* at least one parameter it identifies moved more than SHIFT_SIGMAS standard errors (both
  calibrations' combined) from the early calibration's value, or the parameters both identify moved
  together beyond the same level (:func:`moved_jointly`): a flow gain and a load the record fixes
  mostly as a ratio each move less than their own wide sigma when that ratio changes. The early
  calibration's uncertainty is taken where the later one held what it could not identify (at the
  early values): conditional on those parameters (:func:`shift_covariance`).
"""

from __future__ import annotations

import math

import numpy as np

from . import output_error as oe
from .metrics import velocity
from .simulation import Runner

CLOSED_SHARE = 0.5      # of the later part's distance to its ceiling, closed by calibrating on it alone
SHIFT_SIGMAS = 3.0      # a parameter moved by more than this many combined standard errors
STILL_SEARCH_S = 2.0    # the later part starts at the stillest moment within this long of the validation window's start


def still_start(rec, start: int, joints: list[str]) -> int:
    """The sample within STILL_SEARCH_S of ``start`` where the measured joints move least (smoothed
    speed over 0.1 s): a simulation started there from rest starts as the rig did."""
    span = max(1, int(round(STILL_SEARCH_S / rec.dt)))
    end = min(rec.n - 1, start + span)
    if end <= start:
        return start
    w = max(1, int(round(0.1 / rec.dt)))
    speed = np.zeros(end - start)
    for j in joints:
        v = np.abs(velocity(rec.angles[j], rec.dt))[start:end]
        speed += np.convolve(v, np.ones(w) / w, mode="same") / (np.max(np.abs(v)) or 1.0)
    return start + int(np.argmin(speed))


def _score(fits: dict) -> float:
    return float(np.mean([f["score"] for f in fits.values()]))


def check(model, rec, start: int, joints: list[str], substep: float | None, changes: list[dict],
          ceilings: dict[str, dict[str, float]], calibrate, early: oe.Problem, early_runner: Runner,
          early_ceilings: dict[str, dict[str, float]], first: oe.FitResult | None = None) -> dict:
    """The change of the rig between the record's first part and its part from ``start`` on.

    ``model``: the baseline calibrated on the first part, with ``changes`` its calibration rows
    (calibration.Calibration.changes); ``ceilings``: the channels' noise ceilings per joint (fit, %);
    ``calibrate(model, runner, problem)``: the same calibration on another record; ``early``: the
    estimation window the model was calibrated on, simulated by ``early_runner``, with its channels'
    noise ceilings ``early_ceilings``; ``first``: the early calibration's fit (its covariance, for
    :func:`moved_jointly`). Returns {} when the later part is not explained by calibrating on it
    alone, the early part is missed as much, or no parameter moved; otherwise {'from_s',
    'score_before', 'score_after', 'ceiling', 'score_first', 'ceiling_first', 'moved': [{parameter,
    first, last, sigma, sigmas, unit}]}, with 'jointly': {chi2, dof, level} where the parameters
    moved only together."""
    s0 = still_start(rec, start, joints)
    late = rec.tail(s0)
    runner = Runner(late, substep)
    prob = oe.Problem(late, joints, pressures=late.has_pressures)
    before = runner.simulate(model)
    if not before.ok:
        return {}
    fits = prob.fits(before)
    score_before = _score(fits)
    ceiling = _ceiling(fits, ceilings, joints)
    own = early_runner.simulate(model, early.n)
    if not own.ok:
        return {}
    own_fits = {j: {c: v for c, v in f.items() if c in ("angle", "velocity", "pressure")}
                for j, f in early.fits(own).items()}
    score_first = float(np.mean([np.mean(list(f.values())) for f in own_fits.values()]))
    ceiling_first = _ceiling(own_fits, early_ceilings, joints)
    if not fits_own_part(score_first, ceiling_first, score_before, ceiling):
        return {}
    cal = calibrate(model, runner, prob)
    after = runner.simulate(cal.spec)
    if not after.ok:
        return {}
    score_after = _score(prob.fits(after))
    if not closes(score_before, score_after, ceiling):
        return {}
    fits = None if first is None else (first, cal.result)
    shifted = moved(changes, cal.changes, fits=fits)
    together = None
    if not shifted and fits is not None:
        together = moved_jointly(changes, cal.changes, *fits)
        if together is not None:
            shifted = moved(changes, cal.changes, 0.0, fits=fits)
    if not shifted:
        return {}
    out = {"from_s": round(float(rec.time[s0]), 3), "score_before": round(score_before, 3),
           "score_after": round(score_after, 3), "ceiling": round(ceiling, 3),
           "score_first": round(score_first, 3), "ceiling_first": round(ceiling_first, 3), "moved": shifted}
    if together is not None:
        out["jointly"] = together
    return out


def _ceiling(fits: dict, ceilings: dict[str, dict[str, float]], joints: list[str]) -> float:
    """The mean over ``joints`` of the noise ceilings of the channels ``fits`` has."""
    return float(np.mean([np.mean([ceilings.get(j, {}).get(c, 100.0) for c in fits[j] if c != "score"])
                          for j in joints]))


def fits_own_part(score_first: float, ceiling_first: float, score_before: float, ceiling: float) -> bool:
    """The early calibration is at most CLOSED_SHARE as far below its own part's noise ceiling
    (``score_first`` against ``ceiling_first``) as below the later part's (``score_before`` against
    ``ceiling``): the misfit came with the later part, not with the model."""
    return ceiling_first - score_first <= CLOSED_SHARE * (ceiling - score_before)


def closes(score_before: float, score_after: float, ceiling: float) -> bool:
    """Calibrating on the later part alone took its score from ``score_before`` at least CLOSED_SHARE
    of the way to its noise ``ceiling``."""
    gap = ceiling - score_before
    return gap > 0 and score_after - score_before >= CLOSED_SHARE * gap


def moved(first: list[dict], last: list[dict], sigmas: float = SHIFT_SIGMAS,
          fits: tuple[oe.FitResult, oe.FitResult] | None = None) -> list[dict]:
    """The parameters both calibrations identify (their ``changes`` rows) whose values differ by more
    than ``sigmas`` combined standard errors, the furthest first. ``fits``: the two calibrations' fits,
    whose covariances give the combined standard errors (:func:`shift_covariance`); without them (or
    where one has none) the rows' own sigmas, combined as independent."""
    pairs = _both(first, last)
    cov = shift_covariance(first, last, *fits) if fits is not None else None
    out = []
    for i, (e, c) in enumerate(pairs):
        sigma = (math.sqrt(max(float(cov[i, i]), 0.0)) if cov is not None
                 else math.hypot(float(c["sigma"]), float(e["sigma"])))
        shift = float(c["value"]) - float(e["value"])
        if sigma > 0 and abs(shift) > sigmas * sigma:
            out.append({"parameter": c["parameter"], "first": float(e["value"]), "last": float(c["value"]),
                        "sigma": sigma, "sigmas": abs(shift) / sigma, "unit": c.get("unit", "")})
    return sorted(out, key=lambda m: -m["sigmas"])


def _both(first: list[dict], last: list[dict]) -> list[tuple[dict, dict]]:
    """(early row, later row) of each parameter both calibrations identify, in the later rows' order."""
    early = {c["parameter"]: c for c in first if c.get("identified")}
    return [(early[c["parameter"]], c) for c in last if c.get("identified") and c["parameter"] in early]


def moved_jointly(first: list[dict], last: list[dict], fit_first: oe.FitResult, fit_last: oe.FitResult) -> dict | None:
    """The shift ``d`` of the parameters both calibrations identify, taken together: ``d' S^-1 d`` with
    ``S`` their shift's covariance (:func:`shift_covariance`), a chi-square with as many degrees of
    freedom as parameters. {'chi2', 'dof', 'level'} when it passes ``level``, the chi-square whose tail
    is that of SHIFT_SIGMAS for one parameter (for one the rule of :func:`moved`); None otherwise, or
    where a covariance is missing."""
    pairs = _both(first, last)
    if not pairs:
        return None
    cov = shift_covariance(first, last, fit_first, fit_last)
    if cov is None:
        return None
    d = np.array([float(c["value"]) - float(e["value"]) for e, c in pairs])
    try:
        q = float(d @ np.linalg.solve(cov, d))
    except np.linalg.LinAlgError:
        return None
    level = oe.sigma_level(SHIFT_SIGMAS, len(pairs))
    if not (math.isfinite(q) and q > level):
        return None
    return {"chi2": round(q, 2), "dof": len(pairs), "level": round(level, 2)}


def shift_covariance(first: list[dict], last: list[dict], fit_first: oe.FitResult,
                     fit_last: oe.FitResult) -> np.ndarray | None:
    """The covariance of the later calibration's values less the early one's, for the parameters both
    identify (:func:`_both`, in its order): the two fits' covariances added (parts of the record that
    share no sample), the early one's conditional on the parameters the later calibration held where
    the early one put them (:func:`held_later`). A flow gain and a load that the early part fixes
    mostly as a ratio are each uncertain alone; the later part, calibrated with the load held, compares
    its flow gain with the early flow gain at that load, whose uncertainty is that across the ratio.
    None where a covariance is missing."""
    keys = [c["parameter"] for _, c in _both(first, last)]
    if not keys:
        return None
    c1 = fit_first.covariance(keys, held_later(first, last, fit_first, fit_last))
    c2 = fit_last.covariance(keys)
    return None if c1 is None or c2 is None else c1 + c2


def held_later(first: list[dict], last: list[dict], fit_first: oe.FitResult, fit_last: oe.FitResult) -> list[str]:
    """The parameters the early calibration fitted and the later one held at the early value (its
    ``changes`` rows say the same value); one the later calibration set elsewhere (back to the spec's)
    is not among them."""
    later_free = {fp.key for fp in fit_last.free}
    early = {c["parameter"]: float(c["value"]) for c in first}
    later = {c["parameter"]: float(c["value"]) for c in last}
    return [fp.key for fp in fit_first.free if fp.key not in later_free and fp.key in early and fp.key in later
            and math.isclose(early[fp.key], later[fp.key], rel_tol=1e-9, abs_tol=0.0)]


def cause(found: dict) -> str:
    """The record cause for :func:`check`'s finding."""
    moved = "; ".join(f"{m['parameter']} {m['first']:.4g} -> {m['last']:.4g}" + (f" {m['unit']}" if m["unit"] else "")
                      + f" ({m['sigmas']:.0f} sigma)" for m in found["moved"])
    j = found.get("jointly")
    if j:
        moved = (f"together (chi-square {j['chi2']:.1f} on {j['dof']} parameters, beyond its {SHIFT_SIGMAS:g}-sigma "
                 f"level {j['level']:.1f}; none beyond {SHIFT_SIGMAS:g} sigma alone): {moved}")
    return (f"the rig changed during the record: calibrated again on the record from {found['from_s']:.1f} s on "
            f"alone, the model fits that part at {found['score_after']:.1f} (its noise ceiling "
            f"{found['ceiling']:.1f}) against "
            f"{found['score_before']:.1f} with the first part's calibration, and moved {moved}. Oil warming up "
            "(leaks grow, seals drag less), a supply that sags, a load picked up or set down do this; "
            "log a rig at working temperature with one load, or diagnose the parts apart (the effects tried are the "
            "closest, not its cause)")
