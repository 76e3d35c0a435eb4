"""Switchable model effects (PyBaMM-style submodels) and their lowering into kernel arrays."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

from ..components.base import Parameter, ParameterError

CATALOG_DOC = "../shared/research/discrepancy-catalog.md"

CITE_CATALOG = "HydroHIL research note 'discrepancy catalog' (signatures and bounds of 16 unmodelled effects)"
CITE_JELALI = "M. Jelali, A. Kroll, Hydraulic Servo-systems: Modelling, Identification and Control, Springer, 2003"


class Effect:
    """A physical effect the nominal model may lack, switched on per joint (or globally).

    Subclasses declare ``name``, ``scope`` ('joint' or 'global'), ``PARAMETERS`` (units, default,
    bounds), ``citation``, the actuator kinds they apply to, and ``lower()``, which writes the
    switch and parameters into the kernel arrays. The docstring states the equation and how the
    simulated output changes when the effect is on (the tests check that statement).
    """

    name: ClassVar[str] = ""
    scope: ClassVar[str] = "joint"
    citation: ClassVar[str] = ""
    PARAMETERS: ClassVar[tuple[Parameter, ...]] = ()
    actuators: ClassVar[tuple[str, ...]] = ("cylinder", "rotary")
    requires_sensor: ClassVar[bool] = False

    @classmethod
    def summary(cls) -> str:
        return (cls.__doc__ or "").strip().splitlines()[0]

    @classmethod
    def describe(cls) -> dict:
        return {
            "name": cls.name,
            "description": cls.summary(),
            "details": " ".join(line.strip() for line in (cls.__doc__ or "").strip().splitlines()[1:] if line.strip()),
            "scope": "per-joint" if cls.scope == "joint" else "global",
            "applies_to": list(cls.actuators),
            "parameters": [p.describe() for p in cls.PARAMETERS],
            "citation": cls.citation,
        }

    @classmethod
    def validate(cls, params: dict[str, Any], where: str) -> dict[str, Any]:
        known = {p.name: p for p in cls.PARAMETERS}
        unknown = sorted(set(params) - set(known))
        if unknown:
            raise ParameterError(
                f"{where}: unknown parameter(s) {', '.join(unknown)} for effect {cls.name!r}; "
                f"known: {', '.join(known) or '(none)'}"
            )
        out = {}
        for p in cls.PARAMETERS:
            out[p.name] = p.validate(params[p.name], where) if p.name in params else p.default
        return out

    @classmethod
    def lower(cls, params: dict[str, Any], lw, a: int | None) -> None:  # pragma: no cover - abstract
        raise NotImplementedError


@dataclass
class EffectInstance:
    """One switched-on effect: its name, the joint it acts on (None for global) and parameters."""

    name: str
    joint: str | None
    params: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict:
        d: dict[str, Any] = {"name": self.name}
        if self.joint is not None:
            d["joint"] = self.joint
        d.update(self.params)
        return d
