"""diagnose: show what the model gets wrong on measured data, name the cause, extend, measure the gain.

The procedure (research note 'discrepancy catalog' §4):

1. align and check the data (record.py): columns, start pose, noise floor, end-stop contact;
2. baseline: calibrate by output error what the record can identify and no effect of the bank could
   stand for (calibration.py: the flow gains, the spec's estimated parameters, ...); parameters it
   cannot identify stay nominal; simulate, compute the fits and the residual tests; say whether the
   record was taken in closed loop (closed_loop.py);
3. screening: signature statistics give initial guesses and the report's evidence (signatures.py);
4. decision: fit every candidate, accept by validation gain, BIC and identifiability, greedily for
   several effects (selection.py); when no single one passes but the residual tests fail, the most
   promising pairs are fitted jointly (masked pairs); refit the result with the default integrator settings;
5. the verdict (decision.py): "discrepancy" with the named effects; "no_significant_discrepancy", the
   null outcome, an answer like any other; "unexplained_discrepancy" when the final model still misses
   the record by far (an angle fit below zero, or far below the noise ceiling with failing residual
   tests), with the residual evidence (residual_evidence.py) instead of the least-bad effect.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..dataset import column_unit
from ..ingest import pressure_band
from . import output_error as oe
from . import (blind_spots, command_hold, command_null, command_scale, conditional, detectability, held_at_extreme, mains_tone,
               outside_range, parameter_drift, polarity, sensor_disturbance, step_timing)
from .calibration import calibrate, is_baseline, plan
from .closed_loop import detect as detect_closed_loop, validation_window
from .command_hold import CHOICES as HOLD_CHOICES
from .beyond_range import BeyondRange, stopped_at_an_end
from .candidates import bank
from .decision import (FAR_NOISE, FAR_POINTS, SIGNIFICANCE, final_check, misses_record, recalibration_kept,
                       residual_explained_pct, rivalry, unexplained_reasons, verdict)
from .metrics import noise_std, nrmse_fit, velocity
from .parameters import FreeParameter, free_parameter
from .record import END_STOP_MARGIN, DataCheck, Record, check_record
from .residual_evidence import evidence as residual_evidence
from .residual_evidence import residual_fails
from .residual_tests import autocorrelation, independence, ljung_box, spectrum, transfer_estimate
from .selection import (GRID_SHARE, NOISE_FACTOR, THRESHOLD_POINTS, Evaluation, Setting, affected_joints,
                        channel_ceilings, free_list, noise_ceilings, select, without)
from .signatures import joint_signatures, public
from .side_by_side import SideBySide
from .simulation import Outputs, Runner, choose_numerics, model_spec
from .validation_split import validation_start


@dataclass
class Diagnosis:
    robot: str
    record: Record
    validation: Record
    split: int                              # first validation sample in ``validation``
    check: DataCheck
    numerics: dict
    baseline_spec: object
    extended_spec: object
    baseline_out: Outputs
    extended_out: Outputs
    baseline_fits: dict
    extended_fits: dict
    calibration: dict
    selected: list[dict]
    candidates: list[dict]
    evaluations: list[list[Evaluation]]
    signatures: dict
    tests: dict
    stopped: str
    ceiling: float
    notes: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    closed_loop: dict = field(default_factory=dict)   # closed_loop.detect's answer
    unexplained: dict = field(default_factory=dict)   # why and where the record is left unexplained
    pairs: list[dict] = field(default_factory=list)   # the masked-pair fits, when a pair search ran
    channel_ceilings: dict = field(default_factory=dict)   # joint -> channel -> noise ceiling (fit, %)
    restart_s: float | None = None   # the validation angle restarts from the record this often (closed loop)
    detectable: list[dict] = field(default_factory=list)   # detectability.shown: what the record could show
    split_moved: str = ""   # why the validation part is not the record's last 40 % ("" where it is)
    split_kept: str = ""    # why it is although a part of it holds still on a joint that moves

    @property
    def verdict(self) -> str:
        return verdict(bool(self.selected), bool(self.unexplained))

    def to_json(self) -> dict:
        return {
            "robot": self.robot,
            "verdict": self.verdict,
            "baseline": {"fit": {j: f["angle"] for j, f in self.baseline_fits.items()},
                         "score": {j: f["score"] for j, f in self.baseline_fits.items() if "score" in f},
                         "channels": self.baseline_fits},
            "extended": {"fit": {j: f["angle"] for j, f in self.extended_fits.items()},
                         "score": {j: f["score"] for j, f in self.extended_fits.items() if "score" in f},
                         "residual_explained_pct": {
                             j: _pct(residual_explained_pct(f["score"] - self.baseline_fits[j]["score"],
                                                            self.baseline_fits[j]["score"]))
                             for j, f in self.extended_fits.items() if "score" in f and "score" in self.baseline_fits[j]},
                         "channels": self.extended_fits},
            "selected": self.selected,
            "candidates": self.candidates,
            "pairs": self.pairs,
            "decision": {
                "gain": "validation gain of the joint's score: mean NRMSE fit (percent) of angle, velocity and, "
                        "when recorded, chamber pressures; on a closed-loop record also of the angle restarted from "
                        "the record every validation.angle_restart_s ('restarted')",
                "threshold_points": THRESHOLD_POINTS, "noise_factor": NOISE_FACTOR,
                "score_ceiling": self.ceiling, "stopped": self.stopped,
                "channel_ceilings": self.channel_ceilings,
                "residual_explained_pct": "share of the baseline's normalised residual a gain removes: "
                                          "100 gain / (100 - baseline score)",
                "far_points": FAR_POINTS,
                "far_noise": FAR_NOISE,
            },
            "validation": {"source": self.validation.source, "first_sample": self.split,
                           "start_s": float(self.validation.time[self.split]), "samples": int(self.validation.n - self.split),
                           "angle_restart_s": self.restart_s, "moved": self.split_moved or None,
                           "kept": self.split_kept or None},
            "calibration": self.calibration,
            "closed_loop": bool(self.closed_loop.get("closed_loop", False)),
            "closed_loop_evidence": self.closed_loop,
            "data": self.check.to_dict() | {"targets": self.record.targets, "pressures": self.record.has_pressures,
                                            "notes": self.notes},
            "numerics": self.numerics,
            "signatures": {j: public(s) for j, s in self.signatures.items()},
            "residual_tests": {k: {j: public(v) for j, v in t.items()} for k, t in self.tests.items()},
            "unexplained": self.unexplained,
            "detectable": {"effects": self.detectable, "threshold_points": THRESHOLD_POINTS,
                           "how": "each effect not named (named: false), put into the final model at magnitudes "
                                  "searched by bisection (shares of the way from where it vanishes to the far end of "
                                  "its search range, a factor 2 apart, or 1/16 of the range on a log scale; an "
                                  "effect with no such value, from_weaker_end: from the end of its range where it "
                                  "shows less towards the other, in 1/16 of the range), "
                                  "simulated, the calibrated parameters refitted to it to first order; shows_from: "
                                  "the smallest magnitude whose expected gain reaches the threshold (null: not within "
                                  "the range); each named effect (named: true) the same on the calibrated baseline. "
                                  "An estimate on the first half of the estimation window with one noise draw; a "
                                  "ladder that shows nothing there is searched again on the whole estimation window "
                                  "(window: which one)"},
            "timings_s": self.timings,
        }


MAX_ESTIMATION_SAMPLES = 24000   # longer records are fitted on their first 24000 samples (cost per fit)
HELD_BECAUSE = ("held at the effect's default: free, with the rest refitted, it gains less than the threshold on "
                "the validation data, so the record does not show it apart from the effect's principal parameter")
MIN_WINDOW_SAMPLES = 10   # a restart anchors on the smoothed reading (5 samples at 50 Hz): windows are longer


def _numerics(model, rec: Record, val: Record | None, vrec: Record) -> tuple[Runner, Runner, dict]:
    """The fast runners for the candidate fits (estimation record, validation record) and what was
    compared: the coarsest step checked over every sample the fits simulate, the validation part
    included (a coarse step can hold on the first and drift on the second)."""
    fast, numerics = choose_numerics(model, rec)
    if val is not None:
        vchk, vnumerics = choose_numerics(model, val)
        numerics["validation"] = vnumerics
        if (vchk.substep or 0.0) < (fast.substep or 0.0):
            fast = Runner(rec, vchk.substep)
            numerics["substep"] = vnumerics["substep"]
    return fast, Runner(vrec, fast.substep), numerics


def _numerics_again(model, fast: Runner, vfast: Runner, vprob: oe.Problem, rec: Record, val: Record | None,
                    vrec: Record, numerics: dict) -> tuple[Runner, Runner]:
    """The fast runners, chosen again on ``model`` (the calibrated one) where it diverges at their
    step over the validation part: the step was checked on the nominal model, and a calibrated one
    may need a finer one. Says so in ``numerics`` (``calibrated_model``)."""
    if fast.substep is None or vfast.simulate(model, vprob.n).ok:
        return fast, vfast
    coarse = fast.substep
    fast, vfast, again = _numerics(model, rec, val, vrec)
    numerics["calibrated_model"] = {**again, "nominal_model_substep": coarse,
                                    "because": f"the calibrated model diverged at the nominal model's step of {coarse:g} s"}
    numerics["substep"] = again["substep"]
    return fast, vfast


def _split(rec: Record, val: Record | None, targets: list[str],
           notes: list[str]) -> tuple[oe.Problem, oe.Problem, Record, int, str, str]:
    """Estimation and validation problems: the first 60 % and the last 40 % of a single record (split
    within the joints' motion where a part of that holds still on one: validation_split.py, whose
    reasons are the last two items, why the split moved and why it stayed though a part holds still,
    "" where there is none), or the whole record and the whole validation record."""
    if val is None:
        n, moved, kept = validation_start(rec, targets)
        if moved or kept:
            notes.append(moved or kept)
        n_est = min(n, MAX_ESTIMATION_SAMPLES)
        if n_est < n:
            notes.append(f"estimation uses the first {n_est} samples ({rec.time[n_est]:.0f} s) of the {n} before the validation part")
        return (oe.Problem(rec, targets, n=n_est), oe.Problem(rec, targets, start=n), rec, n, moved, kept)
    missing = [f"q_{j}" for j in targets if j not in val.angles]
    if missing:
        raise ValueError(f"--validation {val.source}: no column {', '.join(missing)} (the estimation record's measured, "
                         f"commanded joints)")
    n_est = min(rec.n, MAX_ESTIMATION_SAMPLES)
    if n_est < rec.n:
        notes.append(f"estimation uses the first {n_est} samples ({rec.time[n_est]:.0f} s) of {rec.source}")
    return (oe.Problem(rec, targets, n=n_est),
            oe.Problem(val, targets, pressures=rec.has_pressures and val.has_pressures), val, 0, "", "")


def _fits_all(prob: oe.Problem, out: Outputs, rec: Record, start: int) -> dict:
    """Per measured joint: channel fits (and score) on the validation window."""
    fits = prob.fits(out)
    for j, y in rec.angles.items():
        if j not in fits:
            fits[j] = {"angle": nrmse_fit(y[start:], out.angles[j][start:]) if out.ok else -math.inf,
                       "excited": False}
    return fits


def _pressure_noise(rec: Record) -> dict[str, float]:
    return {j: 0.5 * (noise_std(pa) + noise_std(pb)) for j, (pa, pb) in rec.pressures.items()}


def run(spec, rec: Record, val: Record | None = None, *, workers: int = 0, progress: bool = True,
        log=None, effects: list[str] | None = None, backend=None, command_hold: str = "auto") -> Diagnosis:
    """``backend`` (:mod:`sim_core.backends`): where the candidate fits run, instead of the local pool.
    ``command_hold``: how the logged commands are replayed between samples (:mod:`.command_hold`):
    'auto' (the record decides, on its closed-loop joints), 'held' or 'period_mean' (every commanded joint)."""
    if command_hold not in HOLD_CHOICES:
        raise ValueError(f"command_hold {command_hold!r}: one of {', '.join(HOLD_CHOICES)}")
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):    # see selection.single_blas_thread
        return _run(spec, rec, val, workers=workers, progress=progress, log=log, effects=effects, backend=backend,
                    hold_choice=command_hold)


def _run(spec, rec: Record, val: Record | None, *, workers: int, progress: bool, log, effects, backend,
         hold_choice: str = "auto", revisit: dict | None = None) -> Diagnosis:
    """``revisit``: this is the second diagnosis of a record whose named model fitted better on the
    other replay of its command ({"first": the first's command_hold, "gain": its points})."""
    log = log or (lambda msg: None)
    t_start = time.perf_counter()
    rec0, val0 = rec, val
    timings: dict = {}
    targets = rec.targets
    check = check_record(rec, spec)
    if val is not None:
        check_record(val, spec)
    notes = list(rec.notes) + (list(val.notes) if val is not None else [])
    for j, share in check.end_stop_share.items():
        if share > 0.05:
            notes.append(f"{j}: {100 * share:.0f} % of the samples are within {END_STOP_MARGIN:g} "
                         f"{column_unit(f'q_{j}', spec)} of a joint limit (end-stop contact)")
    est, vprob, vrec, split, split_moved, split_kept = _split(rec, val, targets, notes)
    m0 = model_spec(spec)

    # numerics for the many candidate fits, checked on this record
    # checked over every sample it will simulate: the estimation part and the validation part (a
    # coarse step can hold on the first and drift on the second)
    fast, vfast, numerics = _numerics(m0, rec, val, vrec)
    accurate, vaccurate = Runner(rec), Runner(vrec)
    timings["numerics"] = time.perf_counter() - t_start

    # baseline: calibrate what the record identifies and no candidate effect could stand for
    pl = plan(m0, rec, effects)
    log(f"calibrating {', '.join(pl.keys)}")
    if not fast.simulate(m0, est.n).ok:
        raise ValueError(f"{rec.source}: the {spec.name} model cannot be simulated on this record's input (the state "
                         f"diverged); check the columns against the robot ({', '.join(rec.targets)})")
    def calibrate_side_by_side(*args, **kw):
        """``calibration.calibrate`` with its independent simulations side by side (a rig frees half a
        dozen parameters, each a Jacobian column, while the other core would idle)."""
        with SideBySide(workers if backend is None else 1) as side:
            return calibrate(*args, side=side, **kw)

    cal = calibrate_side_by_side(m0, fast, est, free=pl.free, why=pl.why)
    loop = detect_closed_loop(rec, spec)
    logged_val, logged_est = vrec, rec   # the records as logged, before any replay of their commands
    hold_joints = ([j for j, e in loop["joints"].items() if e["closed_loop"]] if hold_choice == command_hold.AUTO
                   else list(targets))
    if revisit is not None:
        hold_joints, hold_choice = revisit["first"]["joints"], command_hold.other(revisit["first"]["replay"])
    hold = None
    if hold_joints:
        # what the valve saw between the logged samples: held, or the period's mean (command_hold.py),
        # each replay with its own calibration (one calibrated on the other's is biased towards it)
        moving = command_hold.replayed(rec, hold_joints)
        m_est = oe.Problem(moving, targets, n=est.n, pressures=est.use_pressures)
        m_fast = Runner(moving, fast.substep)
        m_cal = calibrate_side_by_side(m0, m_fast, m_est, free=pl.free, why=pl.why)
        loop["command_hold"] = hold = command_hold.choose(
            est.fits(fast.simulate(cal.spec, est.n)), m_est.fits(m_fast.simulate(m_cal.spec, est.n)), hold_joints,
            hold_choice)
        if revisit is not None:
            loop["command_hold"] = hold = command_hold.revisited(hold, revisit["first"], revisit["gain"])
        if hold["replay"] == command_hold.PERIOD_MEAN or revisit is not None:
            notes.append(command_hold.note(hold))
        if hold["replay"] == command_hold.PERIOD_MEAN:
            rec, val = moving, (None if val is None else command_hold.replayed(val, hold_joints))
            est, vprob, vrec, split, split_moved, split_kept = _split(rec, val, targets, [])
            fast, vfast = m_fast, Runner(vrec, fast.substep)
            accurate, vaccurate = Runner(rec), Runner(vrec)
            cal = m_cal
        timings["command_hold"] = time.perf_counter() - t_start
    nuisance = {k for k in pl.keys if pl.why.get(k, "").startswith("estimated")}
    base_fast = cal.spec
    fast, vfast = _numerics_again(base_fast, fast, vfast, vprob, rec, val, vrec, numerics)
    for c in cal.changes:
        if not c["identified"]:
            log(f"calibration: {c['parameter']} not identified ({c['not_identified_because']}); kept at {c['nominal']:.6g}")
        else:
            log(f"calibration: {c['parameter']} = {c['value']:.6g} (nominal {c['nominal']:.6g}) {conditional.given(c)}".rstrip()
                + (f"; {c['note']}" if c.get("note") else ""))
    # the candidates refit the identified model parameters with themselves. An effect parameter the
    # calibration switched on stays at its calibrated value (the candidate of that effect refits it),
    # except the spec's estimated ones: those are nuisances of the rig, refitted with every candidate
    # and not offered as discrepancies of their own. The flow gains are the baseline (what the joint's
    # speed scales with): refitted with every candidate even where the calibration, fitting without
    # the effect, sent them back to nominal (a record the nominal model drifts off whatever its flow
    # gain: fitted at a wrong one, candidates compete at making up the speed, not at the record)
    def refit_keys(identified):
        keys = [k for k in identified if not k.startswith("effects.") or k in nuisance]
        return keys + [k for k in pl.keys if is_baseline(k) and k not in keys]

    keys = refit_keys(cal.identified)
    # a large effect the nominal model lacks (a wide deadband) can dominate the baseline misfit so that
    # nothing calibrated is identified; once an effect is named the calibration is redone with it in
    # the model, and what it identifies then is refitted with the candidates that follow
    pending = [c["parameter"] for c in cal.changes if not c["identified"]]
    uncalibrated = {c["parameter"]: c["nominal"] for c in cal.changes}
    recalibrations: list[dict] = []

    def recalibrate(model, ev, score=None):
        if not pending:
            return model
        # started where the baseline ended; a parameter this calibration cannot identify goes back to
        # the spec's value, not to the baseline's: that may have stood in for the effect now in the
        # model (a 0.3 rad sensor offset for a valve offset)
        again = calibrate_side_by_side(model, fast, est, free=pl.free, why=pl.why, nominal=uncalibrated)
        newly = [k for k in again.identified if k in pending]
        entry = {"after": ev.candidate.label, "identified": again.identified, "newly_identified": newly,
                 "changes": again.changes}
        recalibrations.append(entry)
        if not newly:
            return model
        if score is not None:
            before, after = score(model), score(again.spec)
            entry["validation_score"] = [round(before, 3), round(after, 3)]
            if not recalibration_kept(before, after):
                # which newly identified parameter the validation data disagrees with: redone with each
                # in turn held where it is, the best of those that keep the score
                tries = []
                for k in newly:
                    held = calibrate_side_by_side(model, fast, est, free=[fp for fp in pl.free if fp.key != k],
                                                  why=pl.why, nominal=uncalibrated)
                    tries.append((score(held.spec), k, held))
                kept = [t for t in tries if recalibration_kept(before, t[0]) and any(i in pending for i in t[2].identified)]
                if not kept:
                    entry["kept"] = False
                    log(f"recalibration with {ev.candidate.label}: not kept (validation score {before:.2f} -> "
                        f"{after:.2f}, as low with any one parameter held); {', '.join(newly)} stay as they were")
                    return model
                after_held, k, again = max(kept, key=lambda t: t[0])
                newly = [i for i in again.identified if i in pending]
                entry.update(identified=again.identified, newly_identified=newly, changes=again.changes, held=k,
                             validation_score=[round(before, 3), round(after_held, 3)],
                             freed_validation_score=round(after, 3))
                log(f"recalibration with {ev.candidate.label}: {k} held (validation score {before:.2f} -> "
                    f"{after:.2f} with it freed, {after_held:.2f} held)")
        log(f"recalibration with {ev.candidate.label}: {', '.join(newly)} now identified")
        keys[:] = refit_keys(again.identified)
        for k in newly:
            pending.remove(k)
        return again.spec

    def checkpoint():
        """A callable that puts what ``recalibrate`` changes back as it is now."""
        saved = (list(pending), list(keys), list(recalibrations))

        def back():
            pending[:], keys[:], recalibrations[:] = saved
        return back

    if loop["closed_loop"]:
        notes.append(loop["note"])
        window = validation_window(loop)
        if window is not None and window * vrec.rate < vprob.n - vprob.start:
            vprob = vprob.restarting(max(MIN_WINDOW_SAMPLES, int(round(window * vrec.rate))))
    timings["baseline"] = time.perf_counter() - t_start

    # screening on the estimation data
    out_est = fast.simulate(base_fast, est.n)
    sigs, guesses = {}, {}
    for j in targets:
        inst = [e for e in spec.effects if e.name == "deadband" and e.joint == j]
        sig = joint_signatures(rec.time[: est.n], rec.angles[j][: est.n], out_est.angles[j][: est.n],
                               rec.u(j)[: est.n], check.noise[j], rec.rate,
                               model_deadband=inst[0].params["width"] if inst else 0.0)
        sigs[j] = sig
        guesses[j] = sig["guesses"]
    cands = [c for c in bank(base_fast, targets, guesses, effects) if not {fp.key for fp in c.free} <= nuisance]
    timings["screening"] = time.perf_counter() - t_start

    pnoise = _pressure_noise(rec)
    if val is not None:
        pn_val = _pressure_noise(val)
        noise = {j: noise_std(val.angles[j]) for j in targets}
    else:
        pn_val = pnoise
        noise = {j: check.noise[j] for j in targets}
    st = Setting(fast, est, vfast, vprob, keys, noise, pn_val,
                 grid=oe.Problem(rec, targets, n=int(est.n * GRID_SHARE), pressures=est.use_pressures),
                 ranges={fp.key: fp for fp in pl.free if fp.key in nuisance},
                 uncalibrated={c["parameter"]: c["nominal"] for c in cal.changes if c["parameter"] in nuisance})
    if hold is not None and hold["replay"] == command_hold.PERIOD_MEAN:
        # where in its period each step came is not in the log: what that alone costs a perfect model
        # joins the noise in the channels' ceilings (step_timing.py)
        closed = [j for j in hold["joints"] if loop["joints"].get(j, {}).get("closed_loop")]
        stepped = step_timing.steps(logged_val, loop, closed, spec)
        noise_only = channel_ceilings(st, vprob.joints)
        st.replay_misfit = step_timing.misfit(base_fast, logged_val, vrec, stepped, vprob, vfast)
        with_steps = channel_ceilings(st, vprob.joints)
        hold["step_timing"] = {
            "draws": step_timing.DRAWS,
            "step_periods": {j: len(stepped.get(logged_val.joint_names.index(j), ())) for j in closed},
            "ceiling_points_lost": {j: {ch: round(noise_only[j][ch] - c, 3) for ch, c in chans.items()}
                                    for j, chans in with_steps.items()}}
        timings["step_timing"] = time.perf_counter() - t_start
    def misfit(out) -> bool:
        """Whether a model's residual tests fail on the validation data (``out``: its outputs)."""
        return any(residual_fails(t) for t in residual_tests(vrec, vprob, out, split).values())

    # an estimated parameter the calibration stopped at an end of its declared range stands in for
    # every named effect, freed beyond that end (beyond_range.py)
    beyond = stopped_at_an_end(m0, cal.changes, pl.free, nuisance)
    stand_ins = ({e: pl.stand_ins.get(e, []) + beyond for e in {c.effect for c in cands} | set(pl.stand_ins)}
                 if beyond else pl.stand_ins)
    # masked pairs are searched only where the model's residual tests fail on the validation data
    sel = select(st, cands, base_fast, workers=workers, progress=progress, log=log, backend=backend,
                 recalibrate=recalibrate, stand_ins=stand_ins, checkpoint=checkpoint, misfit=misfit)
    if sel.stand_ins:
        # a stand-in took an effect's place: it is a calibration finding, so the baseline is calibrated
        # again with it freed (the model the named effects, if any, and the report compare against)
        extra = [replace(fp) for fp in {t[1].key: t[1] for t in sel.stand_ins}.values()]
        why = dict(pl.why)
        for ev, fp, value, s_with, s_effect in sel.stand_ins:
            if fp.key in nuisance:
                why[fp.key] = (f"{pl.why[fp.key]}; freed beyond it to [{fp.lower:.4g}, {fp.upper:.4g}] in place of "
                               f"{ev.candidate.label}: explains the record better ({s_with - s_effect:+.2f} points)")
            else:
                why[fp.key] = (f"held for {ev.candidate.effect}, freed in place of {ev.candidate.label}: explains the "
                               f"record as well ({s_with - s_effect:+.2f} points)")
            pl.held.pop(fp.key, None)
        keys_extra = {fp.key for fp in extra}
        st.ranges.update({fp.key: fp for fp in extra if fp.key in st.ranges})   # refitted within the wider range
        pl.free, pl.why = [fp for fp in pl.free if fp.key not in keys_extra] + extra, why
        found_beyond = {fp.key: value for _, fp, value, _, _ in sel.stand_ins if fp.key in nuisance}
        if found_beyond:
            # the parameter beyond its declared range is the finding: calibrated again from where the
            # stand-in's fit ended (from the spec's values it can end in a worse basin), on the model
            # without effects; where it is not identified by itself beside the rig's other estimated
            # parameters it stays where it explained the record, not at the spec's value the record rejected
            start = m0.copy()
            for fp in pl.free:
                fp.apply(start, fp.get(sel.model))
            spec_values = {fp.key: fp.get(m0) for fp in pl.free}
            cal = calibrate_side_by_side(start, fast, est, free=pl.free, why=pl.why,
                                         nominal={**spec_values, **found_beyond})
            for row in cal.changes:
                if row["parameter"] in found_beyond:
                    row["nominal"] = float(spec_values[row["parameter"]])
                    if not row["identified"]:
                        row["note"] = (f"kept at {row['value']:.4g}, where it explained the record in the named effect's "
                                       "place (not identified by itself beside the other estimated parameters)")
        else:
            cal = calibrate_side_by_side(m0, fast, est, free=pl.free, why=pl.why)
        base_fast = cal.spec
        keys[:] = refit_keys(cal.identified)
    timings["selection"] = time.perf_counter() - t_start

    # final refit of the chosen model with the default integrator settings (two Gauss-Newton steps from
    # the fast optimum: the fast substep was checked to move the fits by < 0.25 points and biases the
    # parameters by about 1 %); the baseline keeps its calibration and is re-simulated at the default
    base_acc = base_fast
    with SideBySide(workers if backend is None else 1) as side:
        def refit(model, chosen):
            free = free_list(model, None, [(e.candidate, e.effect_params()) for e in chosen], keys, st.ranges)
            return oe.fit(accurate, est, model, free, max_sims=2 * (len(free) + 1) + 1, tol=1e-3, side=side)

        # every named effect must still be worth the threshold in the final model: removing it (nothing
        # refitted, so the cost is if anything overstated) must lose THRESHOLD_POINTS on the validation
        # data. A greedy pick whose gain came from refitting the others is dropped here.
        kept: dict = {}

        def misses(out) -> bool:
            return misses_record(vprob.fits(out), sel.ceiling, sel.channel_ceilings, misfit(out),
                                 vprob.fits(kept["base"]))

        def needed(fit, i) -> bool:
            # the outputs _contributions just simulated: the model's and the model's without each effect
            return kept["model"] is fit.spec and misses(kept["without"][i]) and not misses(kept["out"])

        def checked(accepted, model):
            return final_check(
                accepted, model, refit=refit, log=log, needed=needed,
                worth=lambda fit, chosen: _contributions(base_fast, fit.spec, chosen, vaccurate, vprob, side, kept,
                                                         resume=fit.outputs),
                remove=lambda fit, ev: without(base_fast, fit.spec, ev.candidate))

        chosen, final = checked(sel.accepted, sel.model)
        dropped = [e for e in sel.accepted if e not in chosen]
        again = sel.resume(chosen, dropped) if sel.resume is not None else None
        if again is not None:          # a pair passed where the search had stopped for a dropped effect
            sel.accepted = again[0]
            chosen, final = checked(*again)
        # what the named effects' values take for granted: the calibration's parameters left at nominal
        reset = {c["parameter"] for c in cal.changes if not c["identified"]}
        held_fps = [fp for fp in pl.free if fp.key in reset]
        hanging = {} if final is None else conditional.elasticities(final, held_fps, accurate, est, side)
        held_ranges = conditional.declared_ranges(held_fps, {c["parameter"]: c["nominal"] for c in cal.changes})
    ext_acc = final.spec if final is not None else base_acc
    sel.accepted = chosen
    accepted = [(e.candidate, e.effect_params()) for e in chosen]
    base_out = kept["base"] if "base" in kept else vaccurate.simulate(base_acc, vprob.n)
    if not accepted:
        ext_out = base_out
    else:
        ext_out = kept["out"] if kept.get("model") is ext_acc else vaccurate.simulate(ext_acc, vprob.n)
    base_fits = _fits_all(vprob, base_out, vrec, split)
    ext_fits = _fits_all(vprob, ext_out, vrec, split)
    timings["final"] = time.perf_counter() - t_start

    def acts_on(c):         # the joints a candidate's gain is taken on: its rivals are on them
        return affected_joints(c, vprob.joints)

    selected = []
    for i, ev in enumerate(sel.accepted):
        c = ev.candidate
        params = {}
        ci = {}
        # of the values that are measured (a parameter of no significance has nothing to correct)
        elasticity = {fp.key.split(".")[-1]: {k: round(e, 3) for k, e in hanging.get(fp.key, {}).items()}
                      for fp in c.free if hanging.get(fp.key) and abs(ev.significance.get(fp.key, 0.0)) >= SIGNIFICANCE}
        for fp in c.free:
            name = fp.key.split(".")[-1]
            v = final.values[fp.key] if final is not None else ev.values[fp.key]
            params[name] = _absent(fp, v, _bound_of(fp.key, final, ev))
            lo_hi = (final.ci95 if final is not None else ev.ci95).get(fp.key, [v, v])
            ci[name] = [float(lo_hi[0]), float(lo_hi[1])]
        spans = {}
        for fp in c.free:
            name = fp.key.split(".")[-1]
            if name in elasticity and math.isfinite(params[name]):
                sp = conditional.span(params[name], hanging[fp.key], held_ranges, fp.lower, fp.upper)
                if sp is not None:
                    spans[name] = sp
        for name, v in ev.held_at_default.items():    # what the record does not show apart from the rest
            params[name] = v
            ci[name] = [v, v]
        item = {"effect": c.effect, "joint": c.joint, "params": params, "ci95": ci, "gain": round(ev.gain, 3),
                "residual_explained_pct": _pct(ev.explained_pct),
                "gain_channels": {k: round(v, 3) for k, v in ev.gain_channels.items()},
                "bic_delta": _num(ev.bic_delta), "noise_spread": round(ev.spread, 4),
                "significance": {fp.key.split(".")[-1]: _num(ev.significance.get(fp.key, 0.0)) for fp in c.free},
                "refit_of_nominal": c.existing, "round": ev.round}
        if ev.explains_record:
            item["explains_record"] = ev.explains_record
        if ev.as_well_beyond_range:
            item["as_well_beyond_range"] = [
                {**r, "decided_by": f"measuring {r['parameter']} (then deleting its [estimated] line)"
                 + ("" if rec.has_pressures else " or recording the chamber pressures")}
                for r in ev.as_well_beyond_range]
        if ev.held_at_default:
            item["held_at_default"] = {name: {"value": v, "because": HELD_BECAUSE} for name, v in ev.held_at_default.items()}
        if elasticity:
            item["elasticity_to_held"] = elasticity
            item["conditional_on"] = sorted({k for row in elasticity.values() for k in conditional.conditional_on(row)})
        if spans:
            item["range_given_held"] = spans
        if ev.pair is None:
            item.update(rivalry(ev, sel.rounds[ev.round - 1], rec.has_pressures, acts_on))
        else:
            partner = next(m for m in ev.pair.candidate.members if m is not c)
            item["named_together_with"] = {"effect": partner.effect, "joint": partner.joint}
            item["alone"] = ev.pair.candidate.alone.get(c.label, {})
            tried = next((pe for pe in sel.pairs if any(p is ev.pair for p in pe)), [ev.pair])
            item.update(rivalry(ev.pair, tried, rec.has_pressures, acts_on))
        selected.append(item)

    candidates = []
    for r, evals in enumerate(sel.rounds, start=1):
        for ev in sorted(evals, key=lambda e: -e.gain):
            candidates.append({
                "effect": ev.candidate.effect, "joint": ev.candidate.joint, "gain": round(ev.gain, 3),
                "residual_explained_pct": _pct(ev.explained_pct),
                "bic_delta": _num(ev.bic_delta), "params": {k: _num(v) for k, v in ev.effect_params().items()},
                "round": r, "accepted": ev in sel.accepted, "rejected_because": ev.reasons,
                "gain_channels": {k: round(v, 3) for k, v in ev.gain_channels.items()},
                "noise_spread": round(ev.spread, 4), "simulations": ev.sims,
            })
            if ev.in_place_of is not None:     # a rival refitted in place of an effect by the exchange pass
                candidates[-1]["in_place_of"] = {"effect": ev.in_place_of.candidate.effect,
                                                 "joint": ev.in_place_of.candidate.joint}

    pairs = []
    for evals in sel.pairs:
        for pe in sorted(evals, key=lambda e: -e.gain):
            pairs.append({
                "members": [{"effect": m.effect, "joint": m.joint} for m in pe.candidate.members],
                "gain": round(pe.gain, 3), "residual_explained_pct": _pct(pe.explained_pct),
                "bic_delta": _num(pe.bic_delta),
                "params": {m.label: {fp.key.split(".")[-1]: _num(pe.values[fp.key]) for fp in m.free}
                           for m in pe.candidate.members},
                "alone": pe.candidate.alone, "round": pe.round,
                "accepted": any(e.pair is pe for e in sel.accepted), "rejected_because": pe.reasons,
                "noise_spread": round(pe.spread, 4), "simulations": pe.sims,
            })

    calib = {"free": pl.keys, "values": {c["parameter"]: c["value"] for c in cal.changes},
             "sigma": {c["parameter"]: c["sigma"] for c in cal.changes}, "ci95": dict(cal.result.ci95),
             "changes": cal.changes, "held": pl.held,
             "identified": cal.identified, "not_identified": [c["parameter"] for c in cal.changes if not c["identified"]],
             "switched_on": [f"{n}@{j}" if j else n for n, j in pl.switched],
             "recalibrations": recalibrations,
             "stand_ins": [_stand_in(ev, fp, value, s_with, s_effect, m0, base_acc, vrec, vfast, vprob.n, split, base_out)
                           for ev, fp, value, s_with, s_effect in sel.stand_ins]}
    tests = {"baseline": residual_tests(vrec, vprob, base_out, split),
             "extended": residual_tests(vrec, vprob, ext_out, split)}
    ceilings = sel.channel_ceilings
    unexplained = _unexplained(vrec, vprob, split, base_fits, ext_fits, ext_out, tests["extended"], sel.ceiling, selected,
                               ceilings, replay_cause=command_hold.cause(loop))
    if unexplained and val is None and cal.identified:
        # a rig that changed while it was logged: calibrated again on the validation part alone
        drift = parameter_drift.check(
            base_fast, rec, split, vprob.joints, fast.substep, cal.changes, ceilings,
            lambda model, runner, prob: calibrate_side_by_side(model, runner, prob, free=pl.free, why=pl.why),
            est, fast, noise_ceilings(est, vprob.joints, noise, pn_val), first=cal.result)
        timings["drift"] = time.perf_counter() - t_start
        if drift:
            unexplained["parameter_drift"] = drift
            causes = unexplained["record_causes"]
            replay = command_hold.cause(loop)
            causes.insert(causes.index(replay) if replay in causes else len(causes), parameter_drift.cause(drift))
    if unexplained:
        # a sign convention the spec has the other way round (sensor, valve wiring) is no effect of the
        # bank: say so, with the replay that fixes it
        signs = polarity.check(base_acc, vrec, vfast, vprob.n, split, base_out, vprob.joints)
        flows = command_scale.flow_gains(m0, base_acc, pl.free)
        if signs:
            unexplained["polarity"] = signs
            # a command logged both reversed and in another scale: neither reversal alone explains it
            both = command_scale.reversed_check(base_acc, vrec, vfast, vprob.n, split, signs, flows)
            if both:
                unexplained["command_reversed_scale"] = both
            unexplained["record_causes"] = (polarity.causes(signs, spec) + command_scale.reversed_causes(both, spec)
                                            + unexplained["record_causes"])
        # a command whose zero is not the valve's null (a unipolar output nulled mid-range) likewise
        nulls = command_null.check(base_acc, vrec, vfast, vprob.n, split, base_out, vprob.joints)
        if nulls:
            unexplained["command_null"] = nulls
            unexplained["record_causes"] = command_null.causes(nulls) + unexplained["record_causes"]
        # a command logged in another scale than the valve saw (a fraction, before an amplifier's gain)
        # (not on a joint whose position lies outside its range: its speeds are in another unit's scale)
        outside = {j: s for j, s in check.outside_range.items() if outside_range.named(s)}
        scale = command_scale.check(base_acc, vrec, vfast, vprob.n, split, base_out,
                                    [j for j in vprob.joints if j not in outside], flows)
        if scale:
            unexplained["command_scale"] = scale
            unexplained["record_causes"] = command_scale.causes(scale, spec) + unexplained["record_causes"]
    if unexplained:
        unexplained["record_causes"] = _unit_causes(check, rec, spec) + unexplained["record_causes"]
    if unexplained and check.held_at_extreme:
        unexplained["record_causes"] = [held_at_extreme.cause(j, f, column_unit(f"q_{j}", spec))
                                        for j, f in check.held_at_extreme.items()] + unexplained["record_causes"]
    if unexplained and selected:
        # a named cause must explain the record: the effects tried stay in the report as the closest
        # candidates, the model is not extended
        for ev in sel.accepted:
            ev.reasons.append("not named: the extended model still leaves the record unexplained")
        for item in candidates + pairs:
            item["accepted"] = False
        selected, sel.accepted = [], []
        ext_acc, ext_out, ext_fits = base_acc, base_out, base_fits
        tests["extended"] = tests["baseline"]
    # the calibrated parameters as the extended model has them: refitted beside the named effects, and
    # a recalibration may have identified more of them than the baseline did (extended.toml carries these)
    calib["refitted_with_effects"] = _refitted(ext_acc, keys, cal.changes, hanging, held_ranges, pl.free) if selected else {}
    this = _score(ext_fits, vprob.joints)     # the answer's validation score (points)
    if selected and hold is not None:
        # the record does not tell a controller faster than its log from a valve half a period slower:
        # what the named values would be under the other replay
        other = _under_other_hold(hold, logged_est, logged_val, ext_acc, sel.accepted, keys, st, est, vprob, fast.substep)
        for item, ev in zip(selected, sel.accepted):
            item["if_command_hold"] = {"replay": other["replay"], "score_points": _num(other["score"] - this),
                                       "params": {fp.key.split(".")[-1]: _num(other["values"].get(fp.key, math.nan))
                                                  for fp in ev.candidate.free if fp.key in other["values"]}}
        timings["other_hold"] = time.perf_counter() - t_start
    if hold is not None and hold_choice == command_hold.AUTO:
        # the baseline chose the replay without the effects named since, or the record is left
        # unexplained with it: diagnosed again the other way, the better answer is the one given
        gain = other["score"] - this if selected else None
        again = command_hold.revisit(hold, gain, unexplained=bool(unexplained))
        if again is not None:
            log(f"command hold: diagnosing again with the command replayed {again} ("
                + (f"the named model fits {gain:+.2f} points better so)" if gain is not None else "unexplained)"))
            second = _run(spec, rec0, val0, workers=workers, progress=progress, log=log, effects=effects,
                          backend=backend, revisit={"first": hold, "gain": gain})
            score2 = _score(second.extended_fits, vprob.joints)
            scores = {hold["replay"]: round(this, 3), again: round(score2, 3)}
            verdicts = {hold["replay"]: verdict(bool(selected), bool(unexplained)), again: second.verdict}
            if command_hold.adopt(this, score2, bool(unexplained), bool(second.unexplained)):
                second.closed_loop["command_hold"]["revisited"].update(score_points=scores, verdicts=verdicts,
                                                                       answer=again)
                second.timings["first_pass"] = round(time.perf_counter() - t_start - second.timings["total"], 2)
                second.timings["total"] = round(time.perf_counter() - t_start, 2)
                return second
            hold["revisited"] = command_hold.revisit_entry(hold["replay"], gain) | {
                "score_points": scores, "verdicts": verdicts, "answer": hold["replay"]}
            notes.append(command_hold.kept_note(hold))
            timings["second_pass"] = round(second.timings["total"], 2)
    calib["blind_spots"] = blind_spots.friction(pl.keys, targets, rec.has_pressures, effects,
                                                {(s["effect"], s["joint"]) for s in selected})
    notes.extend(calib["blind_spots"])
    # what the record could have shown of every effect not named, beside the final model refitted to it
    named = {(m.effect, m.joint) for e in sel.accepted for m in getattr(e.candidate, "members", (e.candidate,))}
    # and of each named effect on the calibrated baseline; on the window the fits rank their starts on
    # (the Jacobians' rows of the estimation window cut to it)
    rows = detectability.rows_within(est, st.grid)
    cal_jac = cal.result.jacobian if cal.identified else None
    ext_jac = final.jacobian if final is not None and selected else cal_jac
    groups = [(ext_acc, None if ext_jac is None else ext_jac[rows], [c for c in cands if (c.effect, c.joint) not in named], False)]
    if selected:
        first = {(c.effect, c.joint): c.free[0].key.split(".")[-1] for c in cands if c.free}
        values = {(s["effect"], s["joint"]): s["params"].get(first.get((s["effect"], s["joint"])))
                  for s in selected}
        groups.append((base_acc, None if cal_jac is None else cal_jac[rows],
                       [c for c in cands if (c.effect, c.joint) in named], True,
                       {k: v for k, v in values.items() if v is not None}))
    with SideBySide(workers if backend is None else 1) as side:
        shows = detectability.shown(groups, fast, st.grid, lambda c: affected_joints(c, est.joints),
                                    threshold=THRESHOLD_POINTS, noise=noise, pressure_noise=pn_val,
                                    restart=vprob.restart, side=side,
                                    whole=(est, [ext_jac] + ([cal_jac] if selected else [])))
    timings["detectable"] = time.perf_counter() - t_start
    timings["total"] = time.perf_counter() - t_start
    return Diagnosis(spec.name, rec, vrec, split, check, numerics, base_acc, ext_acc, base_out, ext_out, base_fits,
                     ext_fits, calib, selected, candidates, sel.rounds, sigs, tests, sel.stopped, sel.ceiling, notes,
                     {k: round(v, 2) for k, v in timings.items()}, loop, unexplained, pairs, ceilings,
                     round(vprob.restart * vrec.dt, 3) if vprob.restart else None, shows, split_moved, split_kept)


def _score(fits: dict, joints: list[str]) -> float:
    return float(np.mean([fits[j]["score"] for j in joints]))


def _unit_causes(check: DataCheck, rec: Record, spec) -> list[str]:
    """A position outside its joint's range and pressures no chamber holds (the record check's
    findings): columns read in another unit than they were logged in, first among a record's causes."""
    tree = spec.tree
    lines = []
    for j, share in check.outside_range.items():
        if outside_range.named(share) and j in rec.angles:
            i = tree.index(spec.joint(j).dof)
            lines.append(outside_range.cause(j, share, rec.angles[j], float(tree.lower[i]), float(tree.upper[i]),
                                             column_unit(f"q_{j}", spec)))
    found = {col: (why, rec.pressures[col[2:-2]][col.endswith("_b")]) for col, why in check.implausible_pressures.items()}
    return lines + pressure_band.causes(found, spec)


def _stand_in(ev, fp, value, s_with, s_effect, spec, model, vrec, runner, n, start, base_out) -> dict:
    """A parameter calibrated in a named effect's place (decision.stand_in) as diagnosis.json's
    ``calibration.stand_ins`` row. One freed beyond its declared range (beyond_range.BeyondRange) also
    gives the spec's value and that range and, for a valve flow gain far off the spec's, the check of the
    command's scale (command_scale.flow_gain) on the calibrated baseline ``model``."""
    row = {"parameter": fp.key, "value": value,
           "in_place_of": {"effect": ev.candidate.effect, "joint": ev.candidate.joint,
                           "params": {k: _num(v) for k, v in ev.effect_params().items()}},
           "score": round(s_with, 3), "score_with_effect": round(s_effect, 3)}
    if isinstance(fp, BeyondRange):
        row.update(nominal=float(fp.get(spec)), declared_range=[float(v) for v in fp.declared], unit=fp.unit)
        flow = command_scale.flow_gains(spec, model, [fp]).get(fp.key.split(".")[1])
        scale = flow and command_scale.flow_gain(model, vrec, runner, n, start, base_out, flow)
        if scale:
            row["command_scale"] = scale
    return row


def _unexplained(vrec: Record, vprob: oe.Problem, split: int, base_fits: dict, ext_fits: dict, ext_out: Outputs,
                 ext_tests: dict, ceiling: float, selected: list[dict], ceilings: dict[str, dict[str, float]],
                 replay_cause: str | None = None) -> dict:
    """decision.unexplained_reasons on the final model, with the residual evidence; {} when the
    model explains the record. ``ceilings``: the channels' noise ceilings per joint. ``replay_cause``:
    on a closed-loop record, how its command was replayed, listed as a cause in the record to check
    (``record_causes``; :func:`command_hold.cause`)."""
    joints = vprob.joints
    score = _score(ext_fits, joints)
    channel_fits = {j: {c: v for c, v in ext_fits[j].items() if c != "score"} for j in joints}
    why = unexplained_reasons(score=score, ceiling=ceiling, angle_fits={j: ext_fits[j]["angle"] for j in joints},
                              residual_fails=any(residual_fails(ext_tests.get(j, {})) for j in joints),
                              base_score=_score(base_fits, joints), channel_fits=channel_fits,
                              channel_ceilings=ceilings,
                              base_channel_fits=base_fits if selected else None, named=bool(selected))
    if not why:
        return {}
    disturbed = sensor_disturbance.found(channel_fits, ceilings, ext_tests)
    mains = mains_tone.found(ext_tests, vrec.time[split: vprob.n], vrec.rate)
    causes = ([sensor_disturbance.cause(j, f) for j, f in disturbed.items()]
              + [mains_tone.cause(j, f) for j, f in mains.items()])
    out = {"because": why, "score": round(score, 3), "score_ceiling": round(ceiling, 3), "far_points": FAR_POINTS,
           "far_noise": FAR_NOISE,
           "channel_ceilings": {j: {c: round(v, 3) for c, v in ch.items()} for j, ch in ceilings.items()},
           "residual_explained_pct": _pct(residual_explained_pct(score - _score(base_fits, joints), _score(base_fits, joints))),
           "closest": [{k: s[k] for k in ("effect", "joint", "params", "gain", "residual_explained_pct") if k in s}
                       for s in selected],
           "evidence": residual_evidence(vrec, vprob, ext_out, split, ext_tests, ext_fits, ceilings),
           "record_causes": causes + ([replay_cause] if replay_cause else [])}
    if disturbed:
        out["sensor_disturbance"] = {j: {"channels": [{"channel": ch, "fit": round(f, 2), "ceiling": round(c, 2)}
                                                      for ch, f, c in d["channels"]],
                                         "largest_autocorrelation": round(d["largest_autocorrelation"], 3)}
                                     for j, d in disturbed.items()}
    if mains:
        out["mains_tone"] = {j: {"frequency_hz": m["peak_hz"], "mains_hz": m["mains_hz"], "harmonic": m["harmonic"],
                                 "alias_hz": m["alias_hz"], "band_hz": list(m["band_hz"]),
                                 "share": round(m["share"], 3), "contrast": round(m["contrast"], 1),
                                 "steadiness_cv": round(m["steadiness_cv"], 3),
                                 "model_motion_ratio": round(m["model_motion_ratio"], 3)}
                             for j, m in mains.items()}
    return out


def _under_other_hold(hold: dict, logged: Record, logged_val: Record, model, accepted: list[Evaluation],
                      keys: list[str], st: Setting, est: oe.Problem, vprob: oe.Problem, substep: float | None) -> dict:
    """The final model refitted (a few Gauss-Newton steps from its values, named effects and calibrated
    parameters free) on the estimation data with the command replayed the other way: held where the
    diagnosis replayed the period mean, and the reverse; and its validation score so replayed.
    ``logged``, ``logged_val``: the estimation and validation records as logged.
    {"replay", "values": key -> value, "score"}."""
    other = command_hold.HELD if hold["replay"] == command_hold.PERIOD_MEAN else command_hold.PERIOD_MEAN

    def replayed(r: Record) -> Record:
        return r if other == command_hold.HELD else command_hold.replayed(r, hold["joints"])

    rec = replayed(logged)
    vrec = rec if logged_val is logged else replayed(logged_val)
    free = free_list(model, None, [(e.candidate, e.effect_params()) for e in accepted], keys, st.ranges)
    res = oe.fit(Runner(rec, substep), oe.Problem(rec, est.joints, n=est.n, pressures=est.use_pressures), model, free,
                 max_sims=4 * (len(free) + 1) + 1, tol=1e-3, uncertainty=False)
    if not res.ok:
        return {"replay": other, "values": {}, "score": -math.inf}
    prob = oe.Problem(vrec, vprob.joints, n=vprob.n, start=vprob.start, pressures=vprob.use_pressures,
                      restart=vprob.restart)
    fits = prob.fits(Runner(vrec, substep).simulate(res.spec, prob.n))
    return {"replay": other, "values": dict(res.values), "score": _score(fits, prob.joints)}


def _pct(v: float):
    return None if v is None or not math.isfinite(v) else round(float(v), 1)


def _contributions(base_spec, model, chosen: list[Evaluation], runner: Runner, prob: oe.Problem, side: SideBySide,
                   kept: dict, resume: Outputs | None = None) -> list[float]:
    """Validation score (points) each chosen effect is worth in ``model``: the score with it minus
    the score with it removed, on the joints it acts on. The simulations run side by side, with the
    baseline's on the first call; ``kept`` keeps the baseline's output ("base") and the model's
    ("model", "out") for the report, and the model's without each effect ("without"). ``resume``:
    the model's fit outputs, which its validation run may continue (Runner.simulate)."""
    specs = [model] + [without(base_spec, model, ev.candidate) for ev in chosen]
    specs += [] if "base" in kept else [base_spec]
    outs = side.simulate(runner, specs, prob.n, resume=[resume] + [None] * (len(specs) - 1))
    if "base" not in kept:
        kept["base"] = outs.pop()
    kept["model"], kept["out"], kept["without"] = model, outs[0], outs[1:]
    full = prob.fits(outs[0])
    worth = []
    for ev, out in zip(chosen, outs[1:]):
        less = prob.fits(out)
        joints = affected_joints(ev.candidate, prob.joints)
        drop = float(np.mean([full[j]["score"] - less[j]["score"] for j in joints]))
        worth.append(drop if math.isfinite(drop) else math.inf)
    return worth


def _bound_of(key: str, final, ev: Evaluation) -> str | None:
    """The search bound ('lower'/'upper') the reported value of ``key`` sits on, if any: the final
    refit's where it fitted that parameter (the value reported is its own), else the round's fit. A
    round's bound is stale once a refit moved the value (a leak's external part held at none, its
    internal part takes the leak off the bound where the round had left it)."""
    if final is not None and any(f.key == key for f in final.free):
        return final.at_bound(key)
    return ev.bounds.get(key)


def _absent(fp: FreeParameter, v: float, side: str | None) -> float:
    """A parameter that ended where its effect vanishes (on the search bound ``side`` that is its
    null) is reported at that value."""
    null = fp.null
    if side and null is not None and math.isfinite(null):
        if (side == "lower" and null <= fp.lower) or (side == "upper" and null >= fp.upper):
            return float(null)
    return float(v)


def _refitted(model, keys: list[str], changes: list[dict], hanging: dict, held_ranges: dict, free: list) -> dict:
    """{key: {value, nominal[, elasticity_to_held, conditional_on, range_given_held]}} of the
    calibrated parameters the final refit fitted beside the named effects, as ``model`` (the extended
    model) has them (``free``: the calibration's FreeParameters, whose ranges bound the spans)."""
    nominal = {c["parameter"]: c["nominal"] for c in changes}
    own = {fp.key: fp for fp in free}
    out = {}
    for k in keys:
        row = {"value": _num(free_parameter(model, k).get(model)), "nominal": _num(nominal.get(k, math.nan))}
        if hanging.get(k):
            conditional.mark(row, hanging[k], held_ranges, own.get(k))
        out[k] = row
    return out


def _num(v: float):
    """A JSON number to 6 significant digits (a leakage coefficient of 3e-13 m^3/(s Pa) is not 0)."""
    return None if v is None or not math.isfinite(v) else float(f"{float(v):.6g}")


def residual_tests(rec: Record, prob: oe.Problem, out: Outputs, start: int) -> dict:
    """Whiteness, independence and spectra of the validation residual, per joint."""
    res = {}
    if not out.ok:
        return res
    for j in prob.joints:
        y = rec.angles[j][start: prob.n]
        yh = out.angles[j][start: prob.n]
        w = velocity(rec.angles[j][: prob.n], rec.dt)[start:]
        wh = velocity(out.angles[j][: prob.n], rec.dt)[start:]
        rw = w - wh
        dec = max(1, int(round(0.075 * rec.rate)))
        q, p = ljung_box(rw[::dec], lags=20)
        rho = autocorrelation(rw[::dec], 20)[1:]          # the same decimated residual, lags 1-20
        ind = independence(rw, rec.u(j)[start: prob.n], wh, rec.rate)
        f, pxx = spectrum(rw, rec.rate)
        H = transfer_estimate(wh, w, rec.rate) if np.ptp(wh) > 0 else None
        res[j] = {"ljung_box_Q": q, "ljung_box_p": p, "autocorrelation": rho.tolist(),
                  "independence": {k: {kk: vv for kk, vv in v.items() if kk not in ("lags_s", "r")} for k, v in ind.items()},
                  "angle_rms": float(np.sqrt(np.mean((y - yh) ** 2))),
                  "_independence": ind, "_spectrum": (f, pxx), "_etfe": H,
                  "_velocity_residual": rw, "_velocity_simulated": wh}
    return res
