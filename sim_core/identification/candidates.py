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
from ..effects.base import clip_grid
from ..model.queries import subtree_mass
from ..model.spec import joint_unit
from .parameters import FreeParameter, effect_key, find_effect

def confusions() -> dict[frozenset, str]:
    """The measurement that separates two effects the fit may confuse, from the effects' own files."""
    out: dict[frozenset, str] = {}
    for eff in EFFECTS.values():
        for other, text in eff.CONFUSIONS.items():
            out[frozenset({eff.name, other})] = text
    return out


SAME_EFFECT = "records at other poses of the joints between them (which link carries it changes the lever)"
DEFAULT_DECIDER = "a second record with a different excitation"


def decider(a: str, b: str, have_pressures: bool) -> str:
    """The measurement that would separate effect ``a`` from ``b``."""
    if a == b:
        return SAME_EFFECT
    text = confusions().get(frozenset({a, b}), DEFAULT_DECIDER)
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


@dataclass
class Pair:
    """Two candidates fitted together (a masked pair): each alone can be absorbed by the calibration
    or cancel the other's sign in the record, so neither passes on its own. Behaves as a Candidate
    whose free parameters are both members' (first's, then second's); ``grid`` holds starting points
    in that order; ``alone`` keeps each member's single-candidate verdict for the report."""

    members: tuple[Candidate, Candidate]
    grid: list[list[float]] = field(default_factory=list)
    alone: dict[str, dict] = field(default_factory=dict)     # label -> {"gain": points, "rejected_because": [...]}
    existing: bool = False
    fixed: dict[str, float] = field(default_factory=dict)

    @property
    def effect(self) -> str:
        return "+".join(m.effect for m in self.members)

    @property
    def joint(self) -> str | None:
        joints = {m.joint for m in self.members}
        return joints.pop() if len(joints) == 1 else None

    @property
    def free(self) -> list[FreeParameter]:
        return [fp for m in self.members for fp in m.free]

    @property
    def label(self) -> str:
        return " + ".join(m.label for m in self.members)

    @property
    def param_names(self) -> list[str]:
        return [fp.key.split(".")[-1] for fp in self.free]

    def prepare(self, spec):
        for m in self.members:
            spec = m.prepare(spec)
        return spec


def _fp(name, joint, pname, lo, hi, log, null, unit=""):
    return FreeParameter(effect_key(name, joint, pname), float(lo), float(hi), log=log, null=null, unit=unit)


def actuator_scales(spec, joint: str) -> dict:
    """Orders of magnitude of one actuator: full-pressure torque (N m) and full valve flow (m^3/s)."""
    js = spec.joint(joint)
    tree = spec.tree
    i = tree.index(js.dof)
    ps = spec.supply["pressure"]
    q_full = js.components["valve"].full_opening_flow(ps)
    if js.kind == "cylinder":
        cyl = js.components["cylinder"]
        arm = cyl.arms(tree, i, np.linspace(tree.lower[i], tree.upper[i], 50))
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
            c = from_hints(spec, eff, j, sc, g.get(name, {}))
            if c is not None:
                out.append(c)
        if "payload" in allowed:
            out.extend(_distal_payloads(spec, j))
    for name, eff in EFFECTS.items():
        if name in allowed and eff.scope == "global":
            c = from_hints(spec, eff, None, {}, {})
            if c is not None:
                out.append(c)
    return out


def from_hints(spec, eff, j: str | None, scales: dict, guess: dict) -> Candidate | None:
    """The effect's own fitting hints (``Effect.candidate``) as a Candidate."""
    inst = find_effect(spec, eff.name, j)
    hints = eff.candidate(spec, j, scales, guess, dict(inst.params) if inst is not None else None)
    if hints is None:
        return None
    # the hints state a revolute joint's units: a prismatic joint's friction is a force, its play in m
    prismatic = j is not None and spec.tree.is_prismatic(spec.joint(j).dof)
    free = [_fp(eff.name, j, pname, lo, hi, log, null, joint_unit(unit, prismatic) if unit else unit)
            for pname, lo, hi, log, null, unit in hints["free"]]
    return Candidate(eff.name, j, free, fixed=dict(hints.get("fixed", {})), grid=[list(g) for g in hints.get("grid", [])],
                     existing=inst is not None)


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
        m = subtree_mass(tree, other.dof)
        lo, hi = -0.8 * float(tree.mass[k]), 4.0 * subtree_mass(tree, spec.joint(j).dof)
        grid = [[v] for v in clip_grid([m * f for f in (-0.3, 0.3, 1.0, 3.0)] + [0.1 * hi], lo, hi)]
        out.append(Candidate("payload", other.name, [_fp("payload", other.name, "mass", lo, hi, False, 0.0, "kg")],
                             fixed={"mass": 0.0}, grid=grid))
    return out
