"""``hydrohil fit``: calibrate chosen parameters on a whole record and report fits with uncertainties.

The search runs with the fast integrator substep checked on the record; the result is polished with
the default substep, which also gives the Jacobian for the uncertainties. Fits are reported per
channel (angle, velocity, pressures) before and after, each with its spread over re-drawn sensor
noise of the size measured in the record.
"""

from __future__ import annotations

import numpy as np

from . import output_error as oe
from . import conditional
from .calibration import (identifiability, is_baseline, jointly_identified, keep_rank, mark_baseline, mark_conditional,
                          mark_elasticities, mark_kept, plan, scan_flow_gains)
from .elimination import eliminate
from .metrics import noise_std
from .parameters import FreeParameter, FreeParameterError, declared, free_parameter
from ..params_file import overrides, write_params
from .record import Record, check_record
from .side_by_side import SideBySide
from .simulation import Runner, choose_numerics, model_spec

NOISE_DRAWS = 16


def prepare_keys(spec, keys: list[str]) -> list[str]:
    """Check the keys; an effect parameter of an effect the model lacks switches that effect on (at
    its defaults, the fit's starting point). Returns the effects switched on."""
    switched = []
    for k in keys:
        parts = k.split(".")
        if parts[0] == "effects":
            declared(spec, k)                                  # a clear error for a bad key
            name = parts[1]
            joint = parts[2] if len(parts) == 4 else None
            if not any(e.name == name and e.joint == joint for e in spec.effects):
                try:
                    spec.enable_effect(name, joint)
                except ValueError as exc:
                    raise FreeParameterError(f"--free {k}: {exc}") from None
                switched.append(f"{name}" + (f"@{joint}" if joint else ""))
            continue
        if len(parts) == 4 and parts[2] == "sensor" and parts[3] in ("noise", "bits", "range"):
            raise FreeParameterError(f"--free {k}: sensor noise and resolution are properties of the data, not fitted")
        if len(parts) == 4 and parts[2] == "sensor" and parts[3] in ("A", "B"):
            raise FreeParameterError(
                f"--free {k}: the model converts and reads back with the same calibration, so A and B cancel; "
                f"fit a calibration error with effects.sensor_gain.{parts[1]}.gain or effects.sensor_offset.{parts[1]}.offset")
    return switched


def channel_spread(prob: oe.Problem, out, noise: dict[str, float], pnoise: dict[str, float]) -> dict[str, dict[str, float]]:
    """Standard deviation of each channel's fit over re-drawn measurement noise."""
    rng = np.random.default_rng(2024)
    samples: dict[str, dict[str, list[float]]] = {}
    sim = prob.simulated(out)       # the same channels in every draw
    for _ in range(NOISE_DRAWS):
        fits = prob.redrawn(out, noise, pnoise, rng).fits_of(sim)
        for j, f in fits.items():
            for c, v in f.items():
                if c != "score":
                    samples.setdefault(j, {}).setdefault(c, []).append(v)
    return {j: {c: float(np.std(v)) for c, v in ch.items()} for j, ch in samples.items()}


def _fits(prob: oe.Problem, before, after, rec: Record) -> dict:
    noise = {j: noise_std(rec.angles[j]) for j in prob.joints}
    pnoise = {j: 0.5 * (noise_std(a) + noise_std(b)) for j, (a, b) in rec.pressures.items()}
    fb, fa = prob.fits(before), prob.fits(after)
    spread = channel_spread(prob, after, noise, pnoise) if after.ok else {}
    res = {}
    for j in prob.joints:
        res[j] = {c: {"before": fb[j][c], "after": fa[j][c], "spread": spread.get(j, {}).get(c, float("nan"))}
                  for c in fa[j] if c != "score"}
    return res


def _narrowed(fp: FreeParameter, v: float, span: float) -> FreeParameter:
    """``fp`` within x/÷ ``span`` of ``v``, inside its own bounds (the polish step's search range)."""
    return FreeParameter(fp.key, max(fp.lower, v / span), min(fp.upper, v * span), log=True, null=fp.null, unit=fp.unit)


def run_fit(spec, rec: Record, keys: list[str] | None, *, val: Record | None = None, max_sims: int = 80,
            out: str | None = None, workers: int = 0) -> dict:
    """Fit ``keys`` (default: the baseline calibration's plan, see calibration.py) and check each
    one's identifiability: a parameter the record does not identify is reported and written at its
    nominal value, the others refitted without it (which go, and when: elimination.py, as the
    baseline calibration of ``diagnose`` does). Independent simulations (the flow-gain scan, the
    Jacobian columns) run side by side in ``workers`` processes (0: one per CPU; the result is the
    same with any number)."""
    with SideBySide(workers) as side:
        return _run_fit(spec, rec, keys, val=val, max_sims=max_sims, out=out, side=side)


def _run_fit(spec, rec: Record, keys: list[str] | None, *, val: Record | None, max_sims: int, out: str | None,
             side: SideBySide) -> dict:
    spec = spec.copy()
    if keys:
        keys = list(keys)
        switched = prepare_keys(spec, keys)
        m0 = model_spec(spec)
        free = [free_parameter(m0, k) for k in keys]      # validates every key (clear errors)
        why = {k: "chosen (--free)" for k in keys}
        held: dict[str, str] = {}
    else:
        m0 = model_spec(spec)
        pl = plan(m0, rec)
        for name, joint in pl.switched:                   # the written file carries them too
            spec.enable_effect(name, joint, **next(e.params for e in m0.effects if e.name == name and e.joint == joint))
        switched = [f"{n}@{j}" if j else n for n, j in pl.switched]
        free, keys, why, held = pl.free, pl.keys, pl.why, pl.held
    nominal = {fp.key: fp.get(m0) for fp in free}
    targets = rec.targets
    check_record(rec, spec)            # what the record shows that no parameter can fit goes to its notes
    prob = oe.Problem(rec, targets)
    fast, numerics = choose_numerics(m0, rec)
    start = scan_flow_gains(m0, fast, prob, keys, side)      # least squares stalls on a jagged cost
    res = oe.fit(fast, prob, start, free, max_sims=max_sims, uncertainty=False, side=side)
    accurate = Runner(rec)
    polish = [_narrowed(fp, res.values[fp.key], 1.5) if fp.log else fp for fp in free]
    final = oe.fit(accurate, prob, res.spec, polish, max_sims=4 * (len(keys) + 1), tol=1e-3, side=side)
    fitted = final
    dropped: dict[str, tuple[str, oe.FitResult]] = {}
    protected: dict[str, str] = {}
    refits = [0]
    if final.ok:
        # what the record cannot identify goes back to nominal, by the calibration's rules (elimination.py)
        def refit(keep, current):
            reset = fitted.spec.copy()
            for fp in polish:
                fp.apply(reset, current.values[fp.key] if fp in keep else nominal[fp.key])
            out = oe.fit(accurate, prob, reset, keep, max_sims=2 * (len(keep) + 1) + 4, tol=1e-3, side=side)
            refits[0] += out.sims
            return out

        keep, final, dropped = eliminate(polish, fitted, identifiability, refit, keep_rank, last=is_baseline,
                                         together=jointly_identified, protected=protected)
        if not keep:
            reset = fitted.spec.copy()
            for fp in polish:
                fp.apply(reset, nominal[fp.key])
            final = oe.FitResult([], {}, final.cost, spec=reset, sims=0)
    verdict = {k: dropped[k][0] if k in dropped else None for k in keys}
    before, after = side.simulate(accurate, [m0, final.spec])
    result = {
        "robot": spec.name, "source": rec.source, "simulations": res.sims + fitted.sims + refits[0],
        "numerics": numerics, "switched_on": switched,
        "parameters": {}, "fit": {rec.source: _fits(prob, before, after, rec)}, "notes": list(rec.notes),
    }
    if val is not None:
        missing = [f"q_{j}" for j in targets if j not in val.angles]
        if missing:
            raise ValueError(f"--validation {val.source}: no column {', '.join(missing)}")
        check_record(val, spec)
        result["notes"] += [f"{val.source}: {n}" for n in val.notes]
        vprob = oe.Problem(val, targets)
        vr = Runner(val)
        result["fit"][val.source] = _fits(vprob, *side.simulate(vr, [m0, final.spec]), val)
    changes = []
    for fp, k in zip(polish, keys):
        ok = verdict[k] is None
        src = final if ok and k in final.values else dropped[k][1] if k in dropped else fitted
        v_fit = src.values[k]
        v = v_fit if ok else nominal[k]
        result["parameters"][k] = {"value": v, "initial": nominal[k], "sigma": src.sigma.get(k, float("nan")),
                                   "ci95": src.ci95.get(k, [v, v]), "unit": fp.unit, "at_bound": src.at_bound(k),
                                   "fitted": v_fit, "identified": ok}
        row = {"parameter": k, "nominal": nominal[k], "fitted": v_fit, "sigma": src.sigma.get(k, float("nan")),
               "identified": ok, "value": v, "unit": fp.unit, "why": why.get(k, "")}
        if not ok:
            row["not_identified_because"] = verdict[k]
            result["parameters"][k]["not_identified_because"] = verdict[k]
        changes.append(row)
    mark_conditional(changes)
    if final.free:
        mark_baseline(changes, identifiability(final), list(dropped))
    mark_kept(changes, protected)
    reset_keys = [fp for fp in polish if verdict[fp.key] is not None]
    if reset_keys and final.free:
        mark_elasticities(changes, conditional.elasticities(final, reset_keys, accurate, prob, side),
                          [fp for fp in free if verdict[fp.key] is not None], free)
        for row in changes:
            for key in ("elasticity_to_held", "range_given_held"):
                if key in row:
                    result["parameters"][row["parameter"]][key] = row[key]
    result["calibration"] = {"changes": changes, "held": held}
    if out:
        configured = spec.copy()
        for k in keys:
            free[keys.index(k)].apply(configured, result["parameters"][k]["value"])
        data = overrides(configured)
        data["diagnosis"] = {"generated_by": "hydrohil fit", "source": rec.source, "free": keys,
                             "sigma": {k: p["sigma"] for k, p in result["parameters"].items()},
                             "fit": {j: {c: v["after"] for c, v in ch.items()} for j, ch in result["fit"][rec.source].items()}}
        write_params(out, data, header=f"Calibrated by 'hydrohil fit' on {rec.source}.\n"
                                       f"Use with: hydrohil simulate --robot {spec.name} --params {out} ...")
    return result
