"""Calibration of nominal parameters by output error (``hydrohil fit`` and diagnose's baseline).

What the baseline frees (:func:`plan`):

* always the valve flow gains (``joints.<j>.valve.rated_flow``) of the commanded, measured joints:
  the number every valve-controlled joint's speed scales with and the one a datasheet gets least right;
* every parameter the spec marks estimated (``[estimated]`` in robot.toml: a path and its range), within
  that range: the user has said the number is a guess;
* the nominal parameters a record can identify, but only when no effect of the candidate bank could
  stand in for them: supply pressure and oil bulk modulus when chamber pressures are recorded, the
  actuators' viscous friction, a payload mass on a joint whose record carries a gravity load and the
  links' masses as a whole (``links.mass_scale``) when one does.
  ``MIMICS`` lists, for each, the bank effects it can masquerade as (a lower bulk modulus *is* the
  ``bulk_modulus`` effect; a viscous friction absorbs most of a Coulomb friction; a payload mass is the
  ``payload`` effect). Freed while such an effect is searched, the calibration would absorb what
  ``diagnose`` exists to name; so for a built-in robot with the whole bank only the flow gains are
  freed, and a restricted bank (``--effects``) frees what no longer competes with it.

A held parameter that is a different cause with an effect's signature (``STAND_IN_FOR``: links 15 %
heavier than the URDF says load a joint as a point mass at its payload point does) is the effect's
stand-in (``Plan.stand_ins``): an effect named by the search must explain the record better than its
stand-in calibrated in its place (selection's stand-in pass); where it does not, the misfit is a
calibration finding.

After the fit each freed parameter is checked: identified when ``|value / sigma| >= 3`` and no
correlation beyond ``CORRELATION_LIMIT`` ties it to another freed parameter (of such a pair the flow
gain is kept: it is the baseline). A parameter that is not identified is reported as such and reset
to its nominal value, the rest refitted (``elimination.py``: which go, and when; a flow gain goes
only when nothing else is left, and kept below ``|value / sigma| = 3`` its row says so and names the
parameters its value is conditional on); a misfit the calibration explains is a calibration finding
(``Calibration.changes``), not an effect.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from . import conditional
from . import output_error as oe
from .elimination import correlated_with, eliminate
from .parameters import FreeParameter, FreeParameterError, declared, free_parameter
from .record import Record
from .simulation import Runner

IDENTIFIED_RATIO = 3.0       # |value / sigma| of an identified parameter
CORRELATION_LIMIT = 0.98     # |correlation| beyond which two freed parameters are one number to the data
GRAVITY_SHARE = 0.05         # gravity torque over the record >= 5 % of the actuator's full torque: mass seen
SUPPLY_SPAN = 1.5            # supply pressure within x/÷ 1.5 of nominal
BULK_SPAN = 3.0              # oil bulk modulus within x/÷ 3
FRICTION_SPAN = 10.0         # viscous friction within x/÷ 10
MASS_SPAN = 1.25             # the links' masses within x/÷ 1.25 (CAD without hoses, oil, bolts)

# nominal parameter (kind) -> bank effects it can masquerade as
MIMICS: dict[str, tuple[str, ...]] = {
    "supply_pressure": ("payload", "valve_asymmetry", "area_ratio", "flow_saturation", "pump_limit"),
    "bulk_modulus": ("bulk_modulus", "line_dynamics", "joint_compliance"),
    "viscous_friction": ("coulomb_friction", "stribeck_friction", "joint_compliance", "hysteresis"),
    "payload_mass": ("payload", "coulomb_friction", "sensor_gain", "valve_asymmetry"),
    "link_masses": ("payload", "coulomb_friction", "sensor_gain", "valve_asymmetry"),
}

# nominal parameter (kind) -> the bank effects it is a different cause of the same signature for: held
# for them, it is their stand-in, and an effect named must beat it (a distributed mass error against a
# point mass)
STAND_IN_FOR: dict[str, tuple[str, ...]] = {
    "link_masses": ("payload",),
}


def default_free(spec, rec: Record) -> list[str]:
    return [f"joints.{j}.valve.rated_flow" for j in rec.targets]


def estimated_ranges(spec) -> dict[str, tuple[float, float]]:
    """The spec's estimated parameters, path -> (lo, hi); {} for a spec that marks none."""
    est = getattr(spec, "estimated", None) or {}
    out = {}
    for k, v in dict(est).items():
        lo, hi = (float(x) for x in v)
        out[str(k)] = (min(lo, hi), max(lo, hi))
    return out


@dataclass
class Plan:
    """What a calibration frees, and why; nominal parameters it leaves alone, and why."""

    free: list[FreeParameter]
    why: dict[str, str]
    held: dict[str, str] = field(default_factory=dict)
    switched: list[tuple[str, str | None]] = field(default_factory=list)   # effects switched on (name, joint)
    # effect name -> held nominal parameters that could stand in for it (STAND_IN_FOR), ready to free
    stand_ins: dict[str, list[FreeParameter]] = field(default_factory=dict)

    @property
    def keys(self) -> list[str]:
        return [fp.key for fp in self.free]


def plan(spec, rec: Record, effects: list[str] | None = None, *, keys: list[str] | None = None) -> Plan:
    """The calibration's free parameters for ``spec`` (a model spec; effect parameters it frees are
    switched on in it) on ``rec``. ``effects``: the candidate bank searched afterwards (None: every
    effect); ``keys``: an explicit list instead of the default rule (``hydrohil fit --free``)."""
    from ..effects import EFFECTS

    if keys is not None:
        return Plan([free_parameter(spec, k) for k in keys], {k: "chosen (--free)" for k in keys})
    bank = set(EFFECTS if effects is None else effects)
    free: list[FreeParameter] = []
    why: dict[str, str] = {}
    held: dict[str, str] = {}
    switched: list[tuple[str, str | None]] = []
    stand_ins: dict[str, list[FreeParameter]] = {}

    def add(fp: FreeParameter, reason: str):
        if fp.key not in why:
            free.append(fp)
            why[fp.key] = reason

    for key, (lo, hi) in estimated_ranges(spec).items():
        try:
            fp = _estimated(spec, rec, key, lo, hi, switched)
        except (FreeParameterError, ValueError) as exc:
            held[key] = f"marked estimated but not fitted: {exc}"
            continue
        if fp is not None:
            add(fp, f"estimated in the spec, range [{lo:g}, {hi:g}]" if fp.key == key else
                f"estimated in the spec: {key} in [{lo:g}, {hi:g}], fitted as the error it causes, "
                f"range [{fp.lower:g}, {fp.upper:g}]")
    estimated = set(why)
    for k in default_free(spec, rec):
        add(free_parameter(spec, k), "valve flow gain (the baseline)")

    def competing(kind: str) -> list[str]:
        return [e for e in MIMICS[kind] if e in bank]

    def consider(key: str, kind: str, make, reason: str):
        if key in estimated or key in why:
            return
        rivals = competing(kind)
        if rivals:
            held[key] = f"held at nominal: could masquerade as {', '.join(rivals)} (mark it estimated to free it)"
            stands_for = [e for e in STAND_IN_FOR.get(kind, ()) if e in rivals]
            fp = make() if stands_for else None
            for effect in stands_for if fp is not None else ():
                stand_ins.setdefault(effect, []).append(fp)
            return
        fp = make()
        if fp is not None:
            add(fp, reason)

    if rec.has_pressures:
        consider("supply.pressure", "supply_pressure", lambda: _span(spec, "supply.pressure", SUPPLY_SPAN),
                 "pressures recorded")
        consider("fluid.bulk_modulus", "bulk_modulus", lambda: _span(spec, "fluid.bulk_modulus", BULK_SPAN),
                 "pressures recorded")
    @functools.cache
    def loaded(j: str) -> bool:
        return gravity_share(spec, rec, j) >= GRAVITY_SHARE

    for j in rec.targets:
        js = spec.joint(j)
        key = f"joints.{j}.{js.kind}.viscous_friction"
        if spec.get(key) > 0:
            consider(key, "viscous_friction", lambda key=key: _span(spec, key, FRICTION_SPAN), "the joint moves")
        key = f"effects.payload.{j}.mass"
        if key not in why and (competing("payload_mass") or loaded(j)):
            consider(key, "payload_mass", lambda j=j: _payload(spec, j, switched), "the record carries a gravity load")
    # a payload mass freed already carries what the links' masses would (one number to a one-joint record)
    if not any(k.startswith("effects.payload.") for k in why) and any(loaded(j) for j in rec.targets):
        consider("links.mass_scale", "link_masses", lambda: _span(spec, "links.mass_scale", MASS_SPAN),
                 "the record carries a gravity load")
    return Plan(free, why, held, switched, stand_ins)


def _span(spec, key: str, span: float) -> FreeParameter:
    return free_parameter(spec, key, span=span)


def _payload(spec, joint: str, switched) -> FreeParameter:
    from ..effects import EFFECTS

    hints = EFFECTS["payload"].candidate(spec, joint, {}, {}, None)
    _, lo, hi, _, _, unit = hints["free"][0]
    if not any(e.name == "payload" and e.joint == joint for e in spec.effects):
        spec.enable_effect("payload", joint, mass=0.0)
        switched.append(("payload", joint))
    return FreeParameter(f"effects.payload.{joint}.mass", float(lo), float(hi), unit=unit, null=0.0)


def _estimated(spec, rec: Record, key: str, lo: float, hi: float, switched) -> FreeParameter | None:
    """A free parameter for an estimated path. A sensor calibration (``joints.<j>.sensor.A``/``B``)
    is fitted as the sensor gain/offset effect it causes: the record was converted with the spec's
    A and B, the model reads back with the same, so the error shows as y = g q + c with g = A / A_true,
    c = B - B_true."""
    parts = key.split(".")
    if len(parts) == 4 and parts[0] == "joints" and parts[2] == "sensor" and parts[3] in ("A", "B"):
        j = parts[1]
        if j not in rec.angles:
            return None
        nominal = float(spec.get(key))
        if parts[3] == "A":
            if nominal == 0 or lo * nominal <= 0 or hi * nominal <= 0:
                raise ValueError(f"a sensor gain range must have the sign of A = {nominal:g}, got [{lo:g}, {hi:g}]")
            name, pname, a, b, null = "sensor_gain", "gain", nominal / hi, nominal / lo, 1.0
        else:
            name, pname, a, b, null = "sensor_offset", "offset", nominal - hi, nominal - lo, 0.0
        # the effect's own bounds hold too (a wide offset range on a rotary sensor can exceed them)
        eff_key = f"effects.{name}.{j}.{pname}"
        bound = declared(spec, eff_key)
        a, b = max(min(a, b), bound.lower), min(max(a, b), bound.upper)
        if not a < b:
            raise ValueError(f"range [{lo:g}, {hi:g}] leaves no room inside the {name} effect's bounds "
                             f"[{bound.lower:g}, {bound.upper:g}]")
        if not any(e.name == name and e.joint == j for e in spec.effects):
            spec.enable_effect(name, j, **{pname: null})
            switched.append((name, j))
        return FreeParameter(eff_key, a, b, null=null, range_declared=True)
    if parts[0] == "effects":
        declared(spec, key)
        name, joint = parts[1], (parts[2] if len(parts) == 4 else None)
        if not any(e.name == name and e.joint == joint for e in spec.effects):
            spec.enable_effect(name, joint)
            switched.append((name, joint))
    p = declared(spec, key)
    fp = FreeParameter(key, max(lo, p.lower), min(hi, p.upper), unit=p.unit, range_declared=True)
    if not fp.lower < fp.upper:
        raise ValueError(f"range [{lo:g}, {hi:g}] leaves no room inside the parameter's bounds [{p.lower:g}, {p.upper:g}]")
    fp.log = fp.lower > 0 and fp.upper / fp.lower > 3.0
    v = fp.get(spec)
    if not fp.lower <= v <= fp.upper:
        fp.apply(spec, min(max(v, fp.lower), fp.upper))
    return fp


def gravity_share(spec, rec: Record, joint: str) -> float:
    """Largest gravity torque on ``joint`` over the record's angles (other joints at their start),
    as a share of the actuator's full-pressure torque: what a mass on it changes in the record."""
    from ..plant import Plant
    from .candidates import actuator_scales

    if joint not in rec.angles:
        return 0.0
    try:
        ctx = Plant(spec).create_context(seed=0)
    except Exception:       # a spec the plant refuses is reported by the simulation, not here
        return 0.0
    tree = spec.tree
    rb = ctx.rigid_body()
    q = np.array(ctx.q, dtype=float)
    for js in spec.joints:
        if js.name in rec.initial_pose:
            q[tree.index(js.dof)] = rec.initial_pose[js.name]
    i = tree.index(spec.joint(joint).dof)
    y = rec.angles[joint]
    z = np.zeros(tree.n)
    worst = 0.0
    for v in np.linspace(float(np.min(y)), float(np.max(y)), 5):
        q[i] = v
        worst = max(worst, abs(float(rb.inverse_dynamics(q, z, z)[i])))
    full = actuator_scales(spec, joint)["torque"]
    return worst / full if full > 0 else 0.0


@dataclass
class Calibration:
    spec: object                     # the calibrated model spec
    result: oe.FitResult
    free: list[FreeParameter]
    changes: list[dict] = field(default_factory=list)   # one row per freed parameter (see ``calibrate``)
    held: dict[str, str] = field(default_factory=dict)
    switched: list[tuple[str, str | None]] = field(default_factory=list)

    @property
    def identified(self) -> list[str]:
        return [c["parameter"] for c in self.changes if c["identified"]]


# factors around the nominal flow gain tried before least squares
SCAN_FACTORS = (0.5, 0.63, 0.8, 0.9, 1.1, 1.25, 1.6, 2.0)


def calibrate(spec, runner: Runner, problem: oe.Problem, keys: list[str] | None = None, *, span: float = 10.0,
              max_sims: int = 40, uncertainty: bool = True, free: list[FreeParameter] | None = None,
              why: dict[str, str] | None = None, nominal: dict[str, float] | None = None,
              side=None) -> Calibration:
    """Fit ``keys`` (or the ready ``free`` parameters, e.g. a :class:`Plan`'s) of ``spec`` (a model
    spec) on the problem's channels, flow gains from the best point of a coarse scan; then check each
    one's identifiability (see the module docstring), reset those the record cannot identify to
    their nominal values and refit the rest. ``changes`` rows: parameter, nominal, fitted, sigma,
    identified, value (what the calibrated spec holds), unit, why (freed) and, when not identified,
    the reason. ``nominal``: the values a parameter goes back to (default: its value in ``spec``, where
    the fit also starts). ``side`` (:class:`.side_by_side.SideBySide`): where the scan's simulations
    and the fits' Jacobian columns run (the same simulations, so the same calibration)."""
    if free is None:
        free = [free_parameter(spec, k, span=span) for k in keys or []]
    keys = [fp.key for fp in free]
    nominal = {fp.key: (nominal[fp.key] if nominal and fp.key in nominal else fp.get(spec)) for fp in free}
    start = scan_flow_gains(spec, runner, problem, keys, side)
    budget = max_sims + 4 * max(0, len(free) - len([k for k in keys if is_baseline(k)]))
    res = oe.fit(runner, problem, start, free, max_sims=budget, uncertainty=uncertainty, side=side)
    if not uncertainty or not res.ok:
        changes = [_row(fp, nominal, res, res, None, why) for fp in free]
        return Calibration(res.spec, res, free, changes)
    # The parameters the fit cannot pin down go back to nominal, one at a time, the rest refitted
    # each time (elimination.py)
    def refit(keep, current):
        reset = spec.copy()
        for fp in free:
            fp.apply(reset, current.values[fp.key] if fp in keep else nominal[fp.key])
        return oe.fit(runner, problem, reset, keep, max_sims=budget, uncertainty=True, side=side)

    protected: dict[str, str] = {}
    keep, current, dropped = eliminate(free, res, identifiability, refit, keep_rank, last=is_baseline,
                                       together=jointly_identified, protected=protected)
    if keep:
        cal_spec = current.spec
    else:
        cal_spec = spec.copy()
        for fp in free:
            fp.apply(cal_spec, nominal[fp.key])
    final = current
    changes = mark_conditional([_row(fp, nominal, dropped[fp.key][1] if fp.key in dropped else res, final,
                                     dropped[fp.key][0] if fp.key in dropped else None, why) for fp in free])
    mark_baseline(changes, identifiability(final) if keep else {}, list(dropped))
    mark_kept(changes, protected)
    if keep and dropped:
        held = [fp for fp in free if fp.key in dropped]
        mark_elasticities(changes, conditional.elasticities(final, held, runner, problem, side), held, free)
    final.spec = cal_spec
    return Calibration(cal_spec, final, free, changes)


BOUND_SHARE = 1e-3          # within this share of its range (in fit coordinates) of an end, a parameter is at it


def is_baseline(key: str) -> bool:
    """A valve flow gain: the baseline every joint's speed scales with, kept while anything else can go."""
    return key.endswith(".valve.rated_flow")


def at_bound(fp: FreeParameter, value: float) -> str | None:
    """'lower' or 'upper' when ``value`` sits at that end of ``fp``'s range (where the fit stopped on the
    bound: the sigma of the local Jacobian then says nothing), else None."""
    if not (math.isfinite(fp.lower) and math.isfinite(fp.upper)) or fp.upper <= fp.lower:
        return None
    x = fp.to_x(value)
    return "lower" if x <= BOUND_SHARE else "upper" if x >= 1.0 - BOUND_SHARE else None


def jointly_identified(current: oe.FitResult, without: oe.FitResult, k: int) -> bool:
    """Whether resetting ``k`` parameters of ``current`` (refitted as ``without``) raises the cost
    beyond the level of a chi-square with ``k`` degrees of freedom that has the tail of
    ``|value/sigma| = IDENTIFIED_RATIO`` for one, in ``current``'s cost scale; False where that scale
    is unknown (elimination.py: such parameters go one at a time)."""
    scale = current.cost_scale
    if scale is None or not math.isfinite(scale) or scale <= 0 or not without.ok:
        return False
    level = oe.sigma_level(IDENTIFIED_RATIO, k)
    return without.cost - current.cost > level * scale


def identifiability(res: oe.FitResult) -> dict[str, str | None]:
    """Per freed parameter: None when identified, else why not (|value/sigma| < 3, or a correlation
    beyond CORRELATION_LIMIT with another freed parameter; of a correlated pair the flow gain stays)."""
    out: dict[str, str | None] = {}
    keys = [fp.key for fp in res.free]
    for fp in res.free:
        k = fp.key
        v, s = res.values[k], res.sigma.get(k, math.inf)
        ratio = abs(v) / s if s > 0 and math.isfinite(s) else (math.inf if s == 0 else 0.0)
        out[k] = None if ratio >= IDENTIFIED_RATIO else f"|value/sigma| = {ratio:.2g} < {IDENTIFIED_RATIO:g}"
        edge = at_bound(fp, v)
        if edge and out[k] is None:
            out[k] = (f"at the {edge} end of its range [{fp.lower:.4g}, {fp.upper:.4g}]: the record asks for a value "
                      f"beyond it, a misfit that is not this parameter's to absorb")
    C = res.correlation
    if C is not None:
        order = sorted(range(len(keys)), key=lambda i: -keep_rank(keys[i]))
        for a in order:            # of a correlated pair the one that ranks lower in KEEP_ORDER goes
            if out[keys[a]] is not None:
                continue
            for b in range(len(keys)):
                if b == a or out[keys[b]] is not None:
                    continue
                r = C[a, b]
                if np.isfinite(r) and abs(r) > CORRELATION_LIMIT:
                    out[keys[a]] = f"correlation {r:+.3f} with {keys[b]}: the record cannot tell them apart"
                    break
    return out


# of two freed parameters the record cannot tell apart, the one listed first is kept: the flow gain
# is the baseline; a load mass is what users of a rig most often do not know, a supply pressure is
# read off a gauge, so without pressures the load carries what the two explain together
KEEP_ORDER = (".valve.rated_flow", "effects.payload.", ".viscous_friction", "effects.sensor_gain.",
              "effects.sensor_offset.", "fluid.bulk_modulus", "supply.pressure")


def keep_rank(key: str) -> int:
    for i, part in enumerate(KEEP_ORDER):
        if part in key:
            return i
    return len(KEEP_ORDER)


def mark_conditional(changes: list[dict]) -> list[dict]:
    """A kept partner of a parameter dropped for their correlation carries what both explained: its
    row says so (``conditional_on``: the parameters held at nominal that its value depends on)."""
    for c in changes:
        for other in changes:
            if (correlated_with(other.get("not_identified_because")) == c["parameter"]
                    and other["parameter"] not in c.get("conditional_on", [])):
                c.setdefault("conditional_on", []).append(other["parameter"])
    return changes


def mark_baseline(changes: list[dict], verdict: dict[str, str | None], dropped: list[str]) -> list[dict]:
    """A flow gain kept as the baseline although the final fit does not pin it down by itself
    (``verdict``: identifiability of that fit): its row says so (``note``), and that its value
    carries what the parameters reset to nominal (``dropped``) explained with it (``conditional_on``)."""
    for c in changes:
        if c["identified"] and is_baseline(c["parameter"]) and verdict.get(c["parameter"]):
            c["note"] = f"kept as the baseline ({verdict[c['parameter']]})"
            c["conditional_on"] = sorted(set(c.get("conditional_on", [])) | set(dropped))
    return changes


def mark_kept(changes: list[dict], notes: dict[str, str]) -> list[dict]:
    """The rows of parameters the elimination kept although not identified by themselves, or kept
    beside such a one (``notes``: key -> why, from ``eliminate``'s ``protected``), say so (``note``;
    a baseline's note stays)."""
    for c in changes:
        if c["parameter"] in notes:
            c.setdefault("note", notes[c["parameter"]])
    return changes


def mark_elasticities(changes: list[dict], rows: dict[str, dict[str, float]],
                      held: list[FreeParameter] = (), free: list[FreeParameter] = ()) -> list[dict]:
    """An identified parameter's row says how far its value hangs on each one reset to nominal
    (``elasticity_to_held``, conditional.py), and ``conditional_on`` gains those it depends on; with
    the ``held`` parameters whose ranges the spec declares, the span its value takes as they span
    them (``range_given_held``, within its own range among ``free``)."""
    nominal = {c["parameter"]: c["nominal"] for c in changes}
    ranges = conditional.declared_ranges(held, nominal)
    own = {fp.key: fp for fp in free}
    for c in changes:
        e = rows.get(c["parameter"])
        if c["identified"] and e:
            conditional.mark(c, e, ranges, own.get(c["parameter"]))
    return changes


def _row(fp: FreeParameter, nominal: dict, first: oe.FitResult, final: oe.FitResult, reason: str | None,
         why: dict[str, str] | None) -> dict:
    identified = reason is None
    src = final if identified and fp.key in final.values else first
    v_fit = float(src.values.get(fp.key, nominal[fp.key]))
    row = {"parameter": fp.key, "nominal": float(nominal[fp.key]), "fitted": v_fit,
           "sigma": float(src.sigma.get(fp.key, math.nan)), "identified": identified,
           "value": v_fit if identified else float(nominal[fp.key]), "unit": fp.unit,
           "why": (why or {}).get(fp.key, "")}
    if not identified:
        row["not_identified_because"] = reason
    return row


def scan_flow_gains(spec, runner: Runner, problem: oe.Problem, keys: list[str], side=None):
    """``spec`` with each flow gain among ``keys`` moved to the best of ``SCAN_FACTORS`` x its value
    (one joint after the other). Along a flow gain the output-error cost is jagged wherever
    stick-slip, a deadband crossing or end-stop contact switches on or off; a finite-difference
    gradient there is noise and least squares from the nominal value can stall far from the valley
    (seen: a cost 6x the scan's best after 40 simulations). One joint's factors are independent
    simulations: side by side when ``side`` (:class:`.side_by_side.SideBySide`) is given."""
    def costs(specs) -> list[float]:      # each spec the caller's own copy
        return [float(r @ r) for r in map(problem.residuals, oe._simulate_all(runner, specs, problem.n, side))]

    best_spec = spec.copy()
    best = None
    for key in keys:
        if not is_baseline(key):
            continue
        v0 = best_spec.get(key)
        best_v = v0
        trials = []
        for f in SCAN_FACTORS:
            trial = best_spec.copy()
            trial.set(key, v0 * f)
            trials.append(trial)
        found = costs(([best_spec.copy()] if best is None else []) + trials)
        if best is None:
            best, found = found[0], found[1:]
        for f, c in zip(SCAN_FACTORS, found):
            if c < best:
                best, best_v = c, v0 * f
        best_spec.set(key, best_v)
    return best_spec


def format_changes(changes: list[dict]) -> list[str]:
    """One line per freed parameter, for ``fit`` and the log."""
    lines = []
    for c in changes:
        state = (("identified" + (f", {c['note']}" if c.get("note") else "")) if c["identified"]
                 else f"NOT identified ({c.get('not_identified_because')}), kept at nominal")
        lines.append(f"  {c['parameter']}: nominal {c['nominal']:.6g}, fitted {c['fitted']:.6g} +- {c['sigma']:.3g} "
                     f"{c['unit']}".rstrip() + f": {state}" + (f"  [{c['why']}]" if c.get("why") else ""))
    return lines
