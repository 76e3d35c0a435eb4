"""The candidate bank: every effect of ``hydrohil effects`` as a fittable extension of a model.

A candidate is one effect on one joint (or the global one) with the parameters the fit frees, their
search bounds and grid of starting points, and the value at which the effect vanishes ("null", from
which significance is measured). An effect the nominal model already has (the harvester's deadband,
swing leakage, hose lines) is a candidate too: its parameters are refitted from their nominal values,
and its null is that nominal value, so "the deadband is wider than the model's" is a discrepancy.

Secondary parameters are held at their defaults (Coulomb smoothing velocity, the compliance's
actuator-side inertia): they are not identifiable from joint angles and their defaults are typical.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..effects import EFFECTS
from .parameters import FreeParameter, effect_key, find_effect

# measurement that separates two effects the fit may confuse (research note §2 and §6 item 6)
CONFUSIONS: dict[frozenset, str] = {
    frozenset({"valve_asymmetry", "area_ratio"}): "chamber pressures (the area ratio changes the p_A/p_B intensification, a valve asymmetry does not)",
    frozenset({"joint_compliance", "line_dynamics"}): "pressures at the valve port and at the cylinder port, or a second record with another payload (a mechanical mode moves with the load)",
    frozenset({"payload", "valve_asymmetry"}): "records at other poses (a payload scales with cos of the link angle) or chamber pressures",
    frozenset({"payload", "area_ratio"}): "chamber pressures in holds at two poses",
    frozenset({"delay", "spool_lag"}): "a chirp to higher frequencies (a lag rolls the magnitude off, a delay does not)",
    frozenset({"delay", "backlash"}): "slow reversals at several speeds (play costs the same angle at every speed, a delay costs angle in proportion to speed)",
    frozenset({"spool_lag", "backlash"}): "slow reversals at several speeds",
    frozenset({"bulk_modulus", "line_dynamics"}): "pressures at the valve and at the chamber",
    frozenset({"bulk_modulus", "joint_compliance"}): "chamber pressures (air softens the pressure build-up, a mechanical compliance does not)",
    frozenset({"deadband", "coulomb_friction"}): "chamber pressures (friction loads the pressure, a deadband stops the flow)",
    frozenset({"deadband", "hysteresis"}): "small command steps from both directions (hysteresis has memory)",
    frozenset({"hysteresis", "leakage"}): "holds after commands of both signs (hysteresis creeps the previous way, leakage follows the load)",
    frozenset({"flow_saturation", "area_ratio"}): "large commands in both directions",
    frozenset({"flow_saturation", "valve_asymmetry"}): "large and small commands in both directions (saturation depends on |u|)",
    frozenset({"sensor_gain", "payload"}): "a static calibration of the angle sensor against an inclinometer",
    frozenset({"coulomb_friction", "payload"}): "chamber pressures while raising and lowering",
    frozenset({"sensor_offset", "sensor_gain"}): "a record over a wider angle range, through zero (an offset is the same at every angle, a gain error grows with the angle)",
    frozenset({"leakage", "valve_asymmetry"}): "holds at several loads (leakage drifts with the load pressure, an asymmetry only moves with the command)",
    frozenset({"leakage", "area_ratio"}): "holds at several loads, or chamber pressures",
}
SAME_EFFECT = "records at other poses of the joints between them (which link carries it changes the lever)"
DEFAULT_DECIDER = "a second record with a different excitation"


def decider(a: str, b: str, have_pressures: bool) -> str:
    """The measurement that would separate effect ``a`` from ``b``."""
    if a == b:
        return SAME_EFFECT
    text = CONFUSIONS.get(frozenset({a, b}), DEFAULT_DECIDER)
    if have_pressures and text.startswith(("chamber pressures", "pressures")):
        return DEFAULT_DECIDER + " (the recorded pressures did not separate them)"
    return text


@dataclass
class Candidate:
    effect: str
    joint: str | None
    free: list[FreeParameter]
    fixed: dict[str, float] = field(default_factory=dict)
    grid: list[list[float]] = field(default_factory=list)
    existing: bool = False          # the model already has this effect: its parameters are refitted

    @property
    def label(self) -> str:
        return f"{self.effect}@{self.joint}" if self.joint else self.effect

    @property
    def param_names(self) -> list[str]:
        return [fp.key.split(".")[-1] for fp in self.free]

    def start(self, fp: FreeParameter) -> float | None:
        """Where a new effect's parameter starts: where the effect vanishes (its null, or the search
        bound on that side), so the first point of the fit is the model without the effect."""
        null = fp.null
        if null is None or math.isnan(null):
            return None
        return min(max(null, fp.lower), fp.upper)

    def prepare(self, spec):
        """``spec`` with the effect switched on at its starting values (refit ones keep theirs)."""
        s = spec.copy()
        inst = find_effect(s, self.effect, self.joint)
        params = dict(inst.params) if inst is not None else {}
        params.update(self.fixed)
        for fp in self.free:
            name = fp.key.split(".")[-1]
            if inst is None and self.start(fp) is not None:
                params[name] = self.start(fp)
            params.setdefault(name, fp.get(s))
        s.enable_effect(self.effect, self.joint, **params)
        return s


def _fp(name, joint, pname, lo, hi, log, null, unit=""):
    return FreeParameter(effect_key(name, joint, pname), float(lo), float(hi), log=log, null=null, unit=unit)


def _clip_grid(values, lo, hi):
    out = []
    for v in values:
        v = float(min(max(v, lo), hi))
        if all(abs(v - w) > 1e-12 * max(1.0, abs(v)) for w in out):
            out.append(v)
    return out


def subtree_mass(spec, dof: str) -> float:
    tree = spec.tree
    i = tree.index(dof)
    inside = {i}
    for c in range(tree.n):
        p = int(tree.parent[c])
        if p in inside:
            inside.add(c)
    return float(sum(tree.mass[c] for c in inside))


def actuator_scales(spec, joint: str) -> dict:
    """Orders of magnitude of one actuator: full-pressure torque (N m) and full valve flow (m^3/s)."""
    js = spec.joint(joint)
    tree = spec.tree
    i = tree.index(js.dof)
    ps = spec.supply["pressure"]
    v = js.components["valve"]
    q_full = v["rated_flow"] * math.sqrt(ps / v["rated_pressure_drop"])
    if js.kind == "cylinder":
        cyl = js.components["cylinder"]
        c0, d1, d2, lmin, stroke = cyl.linkage(tree.axis[i], tree.lower[i], tree.upper[i])
        qs = np.linspace(tree.lower[i], tree.upper[i], 50)
        arm = (d1 * np.sin(qs) - d2 * np.cos(qs)) / np.sqrt(c0 - 2 * (d1 * np.cos(qs) + d2 * np.sin(qs)))
        torque = ps * cyl.area_a * float(np.max(np.abs(arm)))
        ratio = cyl.area_b / cyl.area_a
    else:
        rot = js.components["rotary"]
        torque = ps * rot["displacement"] * rot["gear_ratio"]
        ratio = None
    return {"torque": torque, "q_full": q_full, "area_ratio": ratio}


def bank(spec, joints: list[str], guesses: dict[str, dict] | None = None, effects: list[str] | None = None) -> list[Candidate]:
    """Candidates for the given (excited, measured) joints plus the global ones.

    ``guesses``: per joint, the signature module's initial guesses {effect: {param: value}}."""
    guesses = guesses or {}
    allowed = set(effects or EFFECTS)
    out: list[Candidate] = []
    for j in joints:
        js = spec.joint(j)
        g = guesses.get(j, {})
        sc = actuator_scales(spec, j)
        for name, eff in EFFECTS.items():
            if name not in allowed or eff.scope != "joint" or js.kind not in eff.actuators:
                continue
            if eff.requires_sensor and not js.sensed:
                continue
            c = _joint_candidate(spec, name, j, sc, g.get(name, {}))
            if c is not None:
                out.append(c)
        if "payload" in allowed:
            out.extend(_distal_payloads(spec, j))
    if "bulk_modulus" in allowed:
        inst = find_effect(spec, "bulk_modulus", None)
        s0 = inst.params["scale"] if inst else 1.0
        a0 = inst.params["air_pressure"] if inst else 5e5
        out.append(Candidate("bulk_modulus", None, [
            _fp("bulk_modulus", None, "scale", 0.05, 2.0, True, s0 if inst else 1.0),
            _fp("bulk_modulus", None, "air_pressure", 1e3, 5e6, True, a0 if inst else 0.0, "Pa"),
        ], grid=[[s * s0, a0] for s in (0.15, 0.3, 0.5, 0.75)] + [[s0, a] for a in (5e4, 2e6)], existing=inst is not None))
    return out


def _joint_candidate(spec, name: str, j: str, sc: dict, guess: dict) -> Candidate | None:
    inst = find_effect(spec, name, j)
    existing = inst is not None
    cur = dict(inst.params) if existing else {}

    def null(p, default):
        return cur[p] if existing else default

    if name == "deadband":
        w0 = cur.get("width", 0.0)
        grid = [0.1, 0.25, 0.5, 0.8, 1.2, 1.8, 2.6, 3.6] if not existing else [w0 * f for f in (0.5, 0.75, 1.25, 1.6, 2.2)]
        if "width" in guess:
            grid.append(guess["width"])
        return Candidate(name, j, [_fp(name, j, "width", 0.0, 4.5, False, null("width", 0.0), "V")],
                         grid=[[v] for v in _clip_grid(grid, 0.0, 4.5)], existing=existing)
    if name == "valve_asymmetry":
        r0 = cur.get("ratio", 1.0)
        grid = [r0 * f for f in (0.6, 0.8, 1.25, 1.6)] + ([guess["ratio"] * r0] if "ratio" in guess else [])
        return Candidate(name, j, [_fp(name, j, "ratio", 0.3, 2.0, True, null("ratio", 1.0))],
                         grid=[[v] for v in _clip_grid(grid, 0.3, 2.0)], existing=existing)
    if name == "spool_lag":
        return Candidate(name, j, [_fp(name, j, "time_constant", 0.002, 0.5, True, null("time_constant", 0.0), "s")],
                         grid=[[v] for v in (0.005, 0.015, 0.04, 0.1, 0.25)], existing=existing)
    if name == "delay":
        grid = [0.005, 0.012, 0.025, 0.045, 0.07, 0.1, 0.15, 0.22, 0.3]
        if "delay" in guess:
            d = guess["delay"]
            grid += [d, 0.7 * d, 1.4 * d]
        return Candidate(name, j, [_fp(name, j, "delay", 0.0, 0.3, False, null("delay", 0.0), "s")],
                         grid=[[v] for v in _clip_grid(grid, 0.0, 0.3)], existing=existing)
    if name == "leakage":
        ci, ce = cur.get("internal", 0.0), cur.get("external", 0.0)
        lo_i, lo_e = 1e-15, 1e-16
        if existing:
            grid = [[max(ci, lo_i) * f, max(ce, lo_e) * f2] for f, f2 in ((0.3, 1.0), (3.0, 1.0), (1.0, 0.3), (1.0, 3.0), (3.0, 3.0))]
        else:
            grid = [[c, lo_e * 10] for c in (1e-13, 1e-12, 1e-11, 5e-11)] + [[lo_i * 10, c] for c in (1e-13, 1e-12, 1e-11)]
        return Candidate(name, j, [
            _fp(name, j, "internal", lo_i, 3e-10, True, null("internal", 0.0), "m^3/(s Pa)"),
            _fp(name, j, "external", lo_e, 1e-10, True, null("external", 0.0), "m^3/(s Pa)"),
        ], fixed={"internal": max(ci, lo_i), "external": max(ce, lo_e)}, grid=grid, existing=existing)
    if name == "coulomb_friction":
        T = sc["torque"]
        lo, hi = 1e-4 * T, 0.6 * T
        grid = [T * f for f in (0.003, 0.01, 0.025, 0.05, 0.1, 0.2, 0.35)]
        return Candidate(name, j, [_fp(name, j, "torque", lo, hi, True, null("torque", 0.0), "N m")],
                         fixed={"smoothing_velocity": cur.get("smoothing_velocity", 0.01)},
                         grid=[[v] for v in _clip_grid(grid, lo, hi)], existing=existing)
    if name == "backlash":
        grid = [0.002, 0.005, 0.01, 0.02, 0.04, 0.08, 0.15]
        if "width" in guess:
            grid.append(guess["width"])
        return Candidate(name, j, [_fp(name, j, "width", 1e-4, 0.2, True, null("width", 0.0), "rad")],
                         grid=[[v] for v in _clip_grid(grid, 1e-4, 0.2)], existing=existing)
    if name == "area_ratio":
        r0 = cur.get("ratio", sc["area_ratio"])
        grid = [r0 * f for f in (0.6, 0.8, 0.9, 1.1, 1.25)]
        return Candidate(name, j, [_fp(name, j, "ratio", 0.1, 0.99, False, r0)],
                         fixed={"ratio": r0}, grid=[[v] for v in _clip_grid(grid, 0.1, 0.99)], existing=existing)
    if name == "flow_saturation":
        q = sc["q_full"]
        lo, hi = 0.02 * q, 2.0 * q
        grid = [q * f for f in (0.08, 0.15, 0.25, 0.4, 0.6, 0.85)]
        return Candidate(name, j, [_fp(name, j, "max_flow", lo, hi, True, null("max_flow", math.inf), "m^3/s")],
                         fixed={"max_flow": hi}, grid=[[v] for v in _clip_grid(grid, lo, hi)], existing=existing)
    if name == "line_dynamics":
        s0 = cur.get("bulk_modulus_scale", 1.0)
        return Candidate(name, j, [_fp(name, j, "bulk_modulus_scale", 0.05, 3.0, True, null("bulk_modulus_scale", math.nan))],
                         fixed={"bulk_modulus_scale": s0},
                         grid=[[v] for v in _clip_grid([s0 * f for f in (0.15, 0.35, 0.6, 1.5)] if existing else [0.1, 0.3, 1.0, 2.0], 0.05, 3.0)],
                         existing=existing)
    if name == "joint_compliance":
        freqs = [0.8, 1.6, 3.0, 5.0, 8.0, 14.0, 25.0]
        if "frequency" in guess:
            freqs.append(guess["frequency"])
        return Candidate(name, j, [
            _fp(name, j, "frequency", 0.3, 60.0, True, null("frequency", math.inf), "Hz"),
            _fp(name, j, "damping_ratio", 0.01, 1.5, True, null("damping_ratio", math.nan)),
        ], fixed={"inertia_ratio": cur.get("inertia_ratio", 0.2), "damping_ratio": cur.get("damping_ratio", 0.1)},
            grid=[[f, 0.1] for f in _clip_grid(freqs, 0.3, 60.0)], existing=existing)
    if name == "payload":
        dof = spec.joint(j).dof
        m = subtree_mass(spec, dof)
        body = spec.tree.index(dof)
        lo, hi = -0.8 * float(spec.tree.mass[body]), 4.0 * m
        grid = [m * f for f in (-0.3, -0.1, 0.05, 0.15, 0.4, 1.0)]
        return Candidate(name, j, [_fp(name, j, "mass", lo, hi, False, null("mass", 0.0), "kg")],
                         fixed={"mass": 0.0}, grid=[[v] for v in _clip_grid(grid, lo, hi)], existing=existing)
    if name == "sensor_offset":
        grid = [[guess["offset"]]] if "offset" in guess else []
        return Candidate(name, j, [_fp(name, j, "offset", -0.5, 0.5, False, null("offset", 0.0), "rad")],
                         fixed={"offset": cur.get("offset", 0.0)}, grid=grid, existing=existing)
    if name == "sensor_gain":
        grid = [[min(max(guess["gain"], 0.55), 1.45)]] if "gain" in guess else []
        return Candidate(name, j, [_fp(name, j, "gain", 0.5, 1.5, False, null("gain", 1.0))],
                         fixed={"gain": cur.get("gain", 1.0)}, grid=grid, existing=existing)
    if name == "hysteresis":
        return Candidate(name, j, [_fp(name, j, "width", 0.0, 3.0, False, null("width", 0.0), "V")],
                         grid=[[v] for v in (0.1, 0.25, 0.45, 0.7, 1.0, 1.5, 2.2)], existing=existing)
    return None


def _distal_payloads(spec, j: str) -> list[Candidate]:
    """A payload at a tool frame further out than ``j``'s link (e.g. HydroLek's 'tool' on j6)."""
    tree = spec.tree
    i = tree.index(spec.joint(j).dof)
    out = []
    for other in spec.joints:
        if other.name == j or not other.settings["payload_frame"]:
            continue
        k = tree.index(other.dof)
        a = k
        while a >= 0 and a != i:
            a = int(tree.parent[a])
        if a != i:
            continue
        m = subtree_mass(spec, other.dof)
        lo, hi = -0.8 * float(tree.mass[k]), 4.0 * subtree_mass(spec, spec.joint(j).dof)
        grid = [[v] for v in _clip_grid([m * f for f in (-0.3, 0.3, 1.0, 3.0)] + [0.1 * hi], lo, hi)]
        out.append(Candidate("payload", other.name, [_fp("payload", other.name, "mass", lo, hi, False, 0.0, "kg")],
                             fixed={"mass": 0.0}, grid=grid))
    return out
