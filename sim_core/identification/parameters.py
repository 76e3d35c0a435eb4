"""Free parameters of an output-error fit: a model parameter path or an effect's parameter.

Keys are the spec's parameter paths (``joints.j2.valve.rated_flow``) or effect parameters written
``effects.<effect>.<joint>.<parameter>`` (``effects.<effect>.<parameter>`` for a global effect).
The optimiser works on a normalised coordinate in [0, 1] across the search bounds, logarithmic for
scale parameters that span decades, so one finite-difference step means the same everywhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..components.base import Parameter
from ..effects import EFFECTS
from ..model.spec import SpecError


class FreeParameterError(ValueError):
    """A --free key does not name a fittable scalar parameter of this model."""


@dataclass
class FreeParameter:
    key: str
    lower: float
    upper: float
    log: bool = False
    null: float | None = None       # value at which an effect vanishes (significance is measured from it)
    unit: str = ""
    range_declared: bool = False    # the range is the spec's own ([estimated]): the user's word on where the value lies

    # ---- coordinates --------------------------------------------------------------------------
    def _t(self, v: float) -> float:
        return math.log(v) if self.log else v

    def to_x(self, v: float) -> float:
        v = min(max(v, self.lower), self.upper)
        a, b = self._t(self.lower), self._t(self.upper)
        return (self._t(v) - a) / (b - a)

    def from_x(self, x: float) -> float:
        a, b = self._t(self.lower), self._t(self.upper)
        t = a + min(max(x, 0.0), 1.0) * (b - a)
        v = math.exp(t) if self.log else t
        return min(max(v, self.lower), self.upper)

    def dv_dx(self, v: float) -> float:
        a, b = self._t(self.lower), self._t(self.upper)
        return (b - a) * (v if self.log else 1.0)

    # ---- the model ----------------------------------------------------------------------------
    @property
    def effect(self) -> tuple[str, str | None, str] | None:
        """(effect, joint, parameter) for an effect key, else None."""
        parts = self.key.split(".")
        if parts[0] != "effects":
            return None
        if len(parts) == 4:
            return parts[1], parts[2], parts[3]
        return parts[1], None, parts[2]

    def get(self, spec) -> float:
        eff = self.effect
        if eff is None:
            return float(spec.get(self.key))
        name, joint, pname = eff
        inst = find_effect(spec, name, joint)
        if inst is None:
            return float(next(p for p in EFFECTS[name].PARAMETERS if p.name == pname).default)
        return float(inst.params[pname])

    def apply(self, spec, value: float) -> None:
        eff = self.effect
        if eff is None:
            spec.set(self.key, float(value))
            return
        name, joint, pname = eff
        inst = find_effect(spec, name, joint)
        params = dict(inst.params) if inst is not None else {}
        params[pname] = float(value)
        spec.enable_effect(name, joint, **params)


def find_effect(spec, name: str, joint: str | None):
    for e in spec.effects:
        if e.name == name and e.joint == joint:
            return e
    return None


def effect_key(name: str, joint: str | None, param: str) -> str:
    return f"effects.{name}.{joint}.{param}" if joint else f"effects.{name}.{param}"


def declared(spec, key: str) -> Parameter:
    """The declared parameter (unit, bounds) behind a key; raises FreeParameterError if none."""
    parts = key.split(".")
    if parts[0] == "effects":
        if len(parts) not in (3, 4) or parts[1] not in EFFECTS:
            raise FreeParameterError(
                f"--free {key}: expected effects.<effect>.<joint>.<parameter> (or effects.<effect>.<parameter> for a "
                f"global effect); effects: {', '.join(EFFECTS)}"
            )
        eff = EFFECTS[parts[1]]
        if (eff.scope == "global") != (len(parts) == 3):
            raise FreeParameterError(f"--free {key}: {parts[1]} is a {'global' if eff.scope == 'global' else 'per-joint'} effect")
        if len(parts) == 4 and parts[2] not in spec.joint_names:
            raise FreeParameterError(f"--free {key}: unknown joint {parts[2]!r}; joints: {', '.join(spec.joint_names)}")
        for p in eff.PARAMETERS:
            if p.name == parts[-1]:
                return p
        raise FreeParameterError(f"--free {key}: {parts[1]} has no parameter {parts[-1]!r}; known: "
                                 f"{', '.join(p.name for p in eff.PARAMETERS)}")
    try:
        comp, name = spec._resolve(key)
    except SpecError as exc:
        raise FreeParameterError(f"--free {key}: {exc}") from None
    for p in comp.PARAMETERS:
        if p.name == name:
            if p.kind != "float":
                raise FreeParameterError(f"--free {key}: not a scalar parameter ({p.kind})")
            return p
    raise FreeParameterError(f"--free {key}: unknown parameter {name!r}; known: {', '.join(comp.values)}")


def free_parameter(spec, key: str, *, span: float = 10.0) -> FreeParameter:
    """A free parameter around its current value: positive scale parameters within x/÷ ``span``
    (log coordinate), others within +-max(|value|, 1) (linear), both inside the declared bounds."""
    p = declared(spec, key)
    fp = FreeParameter(key, p.lower, p.upper, unit=p.unit)
    v = fp.get(spec)
    lo, hi = p.lower, p.upper
    if v > 0 and lo >= 0:
        fp.log = True
        fp.lower = max(lo if lo > 0 else v / span, v / span)
        fp.upper = min(hi, v * span)
    else:
        w = max(abs(v), 1.0)
        fp.lower = max(lo, v - w)
        fp.upper = min(hi, v + w)
    if not fp.lower < fp.upper:
        raise FreeParameterError(f"--free {key}: no room to fit (bounds [{p.lower:g}, {p.upper:g}], value {v:g})")
    return fp
