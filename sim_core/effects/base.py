"""Switchable model effects (PyBaMM-style submodels): the contract every effect file fulfils.

An effect is one file. Its class declares the parameters (units, default, bounds), the citation,
the actuator kinds it applies to and the kernel columns it owns; ``lower()`` writes its switch and
parameters into the kernel arrays. The equations are numba functions in the same file, named in
``HOOKS`` by the phase of the substep they take part in (see ``sim_core.kernel.hooks`` for every
phase, its arguments and how effects compose in it); the kernel generator (``kernel.compose``)
calls them where the effect's switch is on. The same file gives the reference solver its part
(``reference_*`` hooks and ``reference_command``), the stored energy where the effect stores any,
the state it starts from (``reset``) and the hints the diagnosis uses to fit it (``candidate``,
``signature_guess``, ``CONFUSIONS``). The docstring states the equation and how the simulated
output changes when the effect is on (the tests check that statement).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

from ..components.base import Parameter, ParameterError
from ..kernel.layout import AP, GP, col

CATALOG_DOC = "../shared/research/discrepancy-catalog.md"

CITE_CATALOG = "HydroHIL research note 'discrepancy catalog' (signatures and bounds of 16 unmodelled effects)"
CITE_JELALI = "M. Jelali, A. Kroll, Hydraulic Servo-systems: Modelling, Identification and Control, Springer, 2003"


class Effect:
    """A physical effect the nominal model may lack, switched on per joint (or globally).

    Class attributes an effect sets: ``name``, ``scope`` ('joint' or 'global'), ``PARAMETERS``,
    ``citation``, ``actuators`` (kinds it applies to), ``requires_sensor``; ``switch`` (False for an
    effect that only changes parameters at lowering, or whose hooks run always with neutral
    values); ``HOOKS`` {phase: function name in this module}; ``ORDER`` (position in a chained
    phase); ``CONFUSIONS`` {other effect: the measurement that separates the two}.
    """

    name: ClassVar[str] = ""
    scope: ClassVar[str] = "joint"
    citation: ClassVar[str] = ""
    PARAMETERS: ClassVar[tuple[Parameter, ...]] = ()
    actuators: ClassVar[tuple[str, ...]] = ("cylinder", "rotary")
    requires_sensor: ClassVar[bool] = False
    switch: ClassVar[bool] = True
    switch_column: ClassVar[int] = -1
    HOOKS: ClassVar[dict[str, str]] = {}
    ORDER: ClassVar[float] = 0
    CONFUSIONS: ClassVar[dict[str, str]] = {}
    MECHANISM: ClassVar[bool] = False  # changes masses or inertias: lowered before what depends on them

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        if cls.name and cls.switch and "switch_column" not in cls.__dict__:
            table = GP if cls.scope == "global" else AP
            cls.switch_column = table.declare(cls.name, col(f"E_{cls.name.upper()}", "-", f"1.0: {cls.name} switched on"))

    # ---- catalog ------------------------------------------------------------------------------
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

    # ---- lowering -------------------------------------------------------------------------------
    @classmethod
    def lower_neutral(cls, lw, a: int) -> None:
        """Values the kernel reads from this effect's columns while the effect is off (actuator ``a``)."""

    @classmethod
    def lower(cls, params: dict[str, Any], lw, a: int | None) -> None:
        """Write the switch and the parameters (``a`` is None for a global effect)."""
        if cls.switch:
            if cls.scope == "global":
                lw.GP[cls.switch_column] = 1.0
            else:
                lw.AP[a, cls.switch_column] = 1.0

    # ---- state and energy (Python, once per reset or energy check) ------------------------------------
    @classmethod
    def reset(cls, ctx, a: int, q_dof: float, tau: float, on: bool) -> None:
        """Initial values of the effect's state columns of actuator ``a`` at joint position ``q_dof``
        holding torque ``tau``; called whether the effect is on or not (``on``)."""

    @classmethod
    def stored_energy(cls, ctx, a: int, out: dict) -> bool:
        """Add the energy stored in the effect's states to ``out`` (J, by kind); True if it also
        stored the hose and chamber oil (an effect that replaces the lumped hose)."""
        return False

    # ---- reference solver ------------------------------------------------------------------------
    @classmethod
    def command_delay(cls, AP_, a: int) -> float:
        """Dead time (s) the effect puts on the command (reference solver's breakpoints)."""
        return 0.0

    @classmethod
    def reference_command(cls, u: float, a: int, AP_, XS_, memory: dict) -> float:
        """Exact command transform between breakpoints (reference solver); ``memory`` holds the
        effect's state for this actuator across pieces."""
        return u

    # ---- diagnosis hints ----------------------------------------------------------------------------
    @classmethod
    def candidate(cls, spec, joint: str | None, scales: dict, guess: dict, current: dict | None) -> dict | None:
        """How the diagnosis fits this effect on ``joint``: {'free': [(param, lower, upper, log,
        null, unit)], 'fixed': {param: value}, 'grid': [[start values of the free params]]}, or None
        (not fittable). The first free parameter is the effect's principal one: a named effect's others
        are held at their ``PARAMETERS`` default (the typical value) where the record does not show
        them apart from it (``decision.simpler_parameters``). ``scales``: the actuator's full-pressure torque, full valve flow, area ratio;
        ``guess``: initial values from the residual signatures; ``current``: the effect's parameters
        when the model already has it (its parameters are then refitted from there)."""
        return None

    @classmethod
    def signature_guess(cls, sig: dict, context: dict) -> dict | None:
        """Initial parameter values read off the baseline residual's statistics (``sig``, see
        ``identification.signatures``), or None."""
        return None


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


def clip_grid(values, lo, hi) -> list[float]:
    """Distinct values clipped into [lo, hi] (starting grids of a fit)."""
    out: list[float] = []
    for v in values:
        v = float(min(max(v, lo), hi))
        if all(abs(v - w) > 1e-12 * max(1.0, abs(v)) for w in out):
            out.append(v)
    return out
