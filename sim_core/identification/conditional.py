"""What a fitted value takes for granted: the parameters held at their nominal values.

A parameter the calibration could not identify (a rig's supply pressure, logged without pressures)
stays nominal, and what a different value of it would explain is carried by the parameters fitted
beside it. The record fixes a leak's flow, coefficient times pressure drop, so a leak fitted with
the supply 18 % high comes out about 15 % low: the coefficient is conditional on the supply.

Linearised at the optimum, the fitted values follow a held parameter so that the normal equations
stay satisfied: ``dx_f = -(J_f' J_f)^-1 J_f' J_h dx_h`` (every fitted parameter, the calibration's
included, moves with it). The elasticity, percent of the value per percent of the held parameter,
says how far a value hangs on each held one; a user who reads the held value off a gauge later can
correct the value without refitting: ``v * (h_true / h_nominal) ** elasticity``.

The first order is checked against the model before it is reported, as a trust region checks a
Gauss-Newton step: the fitted values moved as it says for the held parameter 10 % either side must
buy at least a quarter of the cost reduction it predicts. Where the fitted parameters have a
direction the record hardly fixes (a backlash's width beside the flow gain and the sensor's gain on
a closed-loop cylinder), the least-squares solution sends them far along it on a sliver of the held
parameter's residual, out of their ranges, where the model does not follow; a refit with the held
value changed does not go there. Then the directions are taken in order of how well the record fixes
them and the most the model confirms are kept (a truncated pseudo-inverse; none: the value does not
depend on the held parameter in any way the model confirms).
"""

from __future__ import annotations

import math

import numpy as np

from .output_error import FitResult, _simulate_all, _spec_at
from .parameters import FreeParameter

# a value that moves by less than 0.2 % per percent of a held parameter does not depend on it for
# practical purposes: a held value 30 % off (the far end of a rig's spec) then moves it less than 6 %
ELASTICITY_LIMIT = 0.2
STEP_REL = 2e-3         # the held parameter's forward step, relative to its value
CHECK_REL = 0.1         # the first order is checked at the held parameter 10 % either side (a gauge's correction)
ACCEPT_RATIO = 0.25     # the share of its predicted cost reduction the model must confirm (a trust region's)
MAX_LOG_FACTOR = 50.0   # span: a factor beyond e^50 on a value is taken as e^50 (the value's own range cuts it)


def elasticities(fit: FitResult, held: list[FreeParameter], runner, problem, side=None) -> dict[str, dict[str, float]]:
    """Per fitted key of ``fit``: {held key: elasticity (% per %)} for each held parameter whose value
    is not zero (an offset held at zero has no percent), from one simulation per held parameter (the
    fitted values' columns are ``fit``'s own Jacobian, taken where its uncertainty was).
    Empty when ``fit`` has no Jacobian (fitted without uncertainty) or nothing is held."""
    J_f = fit.jacobian
    held = [h for h in held if h.key not in fit.values and h.get(fit.spec) != 0.0]
    if J_f is None or fit.residual is None or not held or not fit.free:
        return {}
    specs = []
    for h in held:
        s = fit.spec.copy()
        h.apply(s, h.get(fit.spec) * (1.0 + STEP_REL))
        specs.append(s)
    fit.sims += len(specs)
    outs = _simulate_all(runner, specs, problem.n, side)
    kept = [(h, o) for h, o in zip(held, outs) if o.ok]      # a step the model cannot take says nothing
    if not kept:
        return {}
    held = [h for h, _ in kept]
    # columns per unit of log(h): the residual's change for a relative change of the held value
    J_h = np.column_stack([(problem.residuals(o) - fit.residual) / math.log1p(STEP_REL) for _, o in kept])
    S = confirmed(fit, J_h, held, runner, problem, side)    # dx_f / dlog(h)
    out: dict[str, dict[str, float]] = {}
    for i, fp in enumerate(fit.free):
        v = fit.values[fp.key]
        if v == 0.0:
            continue
        row = {h.key: float(fp.dv_dx(v) * S[i, j] / v) for j, h in enumerate(held)}
        out[fp.key] = {k: e for k, e in row.items() if math.isfinite(e)}
    return out


def confirmed(fit: FitResult, J_h: np.ndarray, held: list[FreeParameter], runner, problem, side=None) -> np.ndarray:
    """dx_f / dlog(h) per held parameter (columns of ``J_h``): the least-squares solution where the
    model confirms it at the held value ``CHECK_REL`` either side (:func:`_ratios`), else the solution
    on the best-fixed directions of ``fit``'s Jacobian that the model confirms, the most of them."""
    U, sv, Vt = np.linalg.svd(fit.jacobian, full_matrices=False)
    # the directions lstsq's default cut-off keeps (singular values in descending order)
    n = int(np.sum(sv > sv[0] * max(fit.jacobian.shape) * np.finfo(float).eps))
    coef = (U[:, :n].T @ J_h) / sv[:n, None]        # per direction and held parameter, per unit log(h)

    def move(k: int, j: int) -> np.ndarray:          # the top-k directions' solution for held parameter j
        return -(Vt[:k].T @ coef[:k, j])

    S = np.column_stack([move(n, j) for j in range(len(held))])
    todo = [j for j, ok in enumerate(_ratios(fit, J_h, held, [(j, S[:, j]) for j in range(len(held))],
                                             runner, problem, side)) if not ok]
    if todo:
        tries = [(j, k) for j in todo for k in range(n - 1, 0, -1)]
        oks = _ratios(fit, J_h, held, [(j, move(k, j)) for j, k in tries], runner, problem, side)
        for j in todo:
            S[:, j] = next((move(k, j) for (jj, k), ok in zip(tries, oks) if jj == j and ok), 0.0)
    return S


def _ratios(fit: FitResult, J_h: np.ndarray, held: list[FreeParameter], moves: list[tuple[int, np.ndarray]],
            runner, problem, side=None) -> list[bool]:
    """Per (held index j, move dx/dlog h_j): whether the model confirms it. The fitted values moved by
    it (within their ranges) with h_j at (1 +- CHECK_REL) of its value, both simulated: the cost must
    fall by at least ACCEPT_RATIO of what the linear model predicts from the unmoved values at that
    h_j (which it must predict to fall)."""
    x, r0, J_f = fit.x, fit.residual, fit.jacobian
    steps = (math.log1p(CHECK_REL), math.log1p(-CHECK_REL))
    specs, plan = [], []
    for j, dx in moves:
        for d in steps:
            xp = np.clip(x + dx * d, 0.0, 1.0)
            s = _spec_at(fit.spec, fit.free, xp)
            held[j].apply(s, held[j].get(fit.spec) * math.exp(d))
            specs.append(s)
            unmoved = r0 + J_h[:, j] * d
            plan.append((float(unmoved @ unmoved), float(np.sum((unmoved + J_f @ (xp - x)) ** 2))))
    fit.sims += len(specs)
    outs = _simulate_all(runner, specs, problem.n, side)
    out = []
    for i in range(len(moves)):
        pair = range(2 * i, 2 * i + 2)
        before = sum(plan[m][0] for m in pair)
        predicted = before - sum(plan[m][1] for m in pair)
        costs = [float(np.sum(problem.residuals(outs[m]) ** 2)) if outs[m].ok else math.inf for m in pair]
        out.append(predicted > 0.0 and before - sum(costs) >= ACCEPT_RATIO * predicted)
    return out


def corrected(value: float, elasticity: dict[str, float], true_over_nominal: dict[str, float]) -> float:
    """``value`` corrected to the true values of the held parameters (each given as true / nominal;
    one not given is taken as right), to first order: ``value * prod (true / nominal) ** e``."""
    for key, e in elasticity.items():
        value *= true_over_nominal.get(key, 1.0) ** e
    return value


def conditional_on(rows: dict[str, float]) -> list[str]:
    """The held parameters a value depends on (|elasticity| >= ELASTICITY_LIMIT), in key order."""
    return sorted(k for k, e in rows.items() if abs(e) >= ELASTICITY_LIMIT)


def declared_ranges(held, nominal: dict[str, float]) -> dict[str, tuple[float, float, float]]:
    """{key: (lower, upper, nominal)} of the ``held`` parameters (FreeParameters) whose range the
    spec declares (``range_declared``); ``nominal``: the values they are held at."""
    return {h.key: (float(h.lower), float(h.upper), float(nominal[h.key]))
            for h in held if h.range_declared and h.key in nominal}


def span(value: float, elasticity: dict[str, float], ranges: dict[str, tuple[float, float, float]],
         lower: float = -math.inf, upper: float = math.inf) -> dict | None:
    """Where ``value`` lies as each held parameter it depends on spans its declared range (``ranges``:
    key -> (lower, upper, nominal)), to first order in the logarithms, ``value * (bound / nominal) ** e``
    for each, the ends multiplied together; within the value's own ``lower``/``upper`` (its range, not
    cut below what it was fitted to). {'lower', 'upper', 'over': {key: [lower, upper]}}; None where it
    depends on no held parameter with a positive declared range (a ratio has no meaning across zero)."""
    lo_log = hi_log = 0.0          # the ends' factors, as logarithms (an elasticity of 1e3 overflows a power)
    over = {}
    for key in conditional_on(elasticity):
        if key not in ranges:
            continue
        a, b, nom = ranges[key]
        if not (a > 0 and b > 0 and nom > 0):
            continue
        e = elasticity[key]
        l1, l2 = e * math.log(a / nom), e * math.log(b / nom)
        lo_log += min(l1, l2)
        hi_log += max(l1, l2)
        over[key] = [a, b]
    if not over:
        return None
    # beyond a factor of e^MAX_LOG_FACTOR the first order says only that the value is not bounded there
    f1, f2 = math.exp(max(lo_log, -MAX_LOG_FACTOR)), math.exp(min(hi_log, MAX_LOG_FACTOR))
    v1, v2 = sorted((value * f1, value * f2))
    return {"lower": min(max(v1, lower), value), "upper": max(min(v2, upper), value), "over": over}


def mark(row: dict, elasticity: dict[str, float], ranges: dict[str, tuple[float, float, float]] | None = None,
         own=None) -> dict:
    """``row`` (a measured value's row) with its ``elasticity_to_held`` and, for each held parameter
    it depends on, ``conditional_on`` extended; with ``ranges`` (:func:`declared_ranges`), where its
    value lies as those span them (``range_given_held``, :func:`span`, within ``own``'s range: the
    row's FreeParameter)."""
    row["elasticity_to_held"] = {k: round(e, 3) for k, e in elasticity.items()}
    depends = conditional_on(elasticity)
    if depends:
        row["conditional_on"] = sorted(set(row.get("conditional_on", [])) | set(depends))
    value = row.get("value")
    if ranges and value is not None and math.isfinite(value):
        s = span(float(value), elasticity, ranges, *((own.lower, own.upper) if own is not None else ()))
        if s is not None:
            row["range_given_held"] = s
    return row


def describe(named: dict) -> list[str]:
    """One line per value of a named effect (a ``selected`` item of the diagnosis) that hangs on a
    held parameter: which, how much, and the correction once its true value is known."""
    lines = []
    spans = named.get("range_given_held", {})
    for param, row in named.get("elasticity_to_held", {}).items():
        for key in conditional_on(row):
            e = row[key]
            lines.append(f"{param} is conditional on {key} held at nominal: {e:+.2f} % per % of it "
                         f"(with its true value, about {param} x (true / nominal) ^ {e:.2f}; without the linearisation: that "
                         f"value in the robot's spec and the record diagnosed again)")
        s = spans.get(param)
        if s:
            lines.append(f"{param} lies between {s['lower']:.4g} and {s['upper']:.4g} {_spanning(s)}, to first order")
    return lines


def given(row: dict) -> str:
    """'given K1 (e1 % per %), K2 at nominal' for a calibration row's ``conditional_on``, with the
    elasticity where the row has one; empty when it depends on nothing held."""
    if not row.get("conditional_on"):
        return ""
    e = row.get("elasticity_to_held") or {}
    held = [f"{k} ({e[k]:+.2f} % per %)" if k in e else k for k in row["conditional_on"]]
    out = f"given {', '.join(held)} at nominal"
    s = row.get("range_given_held")
    if s:
        unit = f" {row['unit']}" if row.get("unit") else ""
        out += f"; {s['lower']:.4g} to {s['upper']:.4g}{unit} {_spanning(s)}"
    return out


def _spanning(s: dict) -> str:
    """'as K spans its declared range' (or 'as K1, K2 span their ...') for a :func:`span`."""
    return f"as {', '.join(s['over'])} {'spans its' if len(s['over']) == 1 else 'span their'} declared range"
