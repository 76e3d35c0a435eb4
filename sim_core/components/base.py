"""Parameter declarations shared by components and effects.

A component (valve, hose, cylinder, ...) declares its parameters with units, bounds and a
description; the numbers live in the robot's TOML spec (data), not in code. Validation happens once,
when a spec or a parameter override is loaded, so bad input is reported by name and never reaches
the compiled kernel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar


class ParameterError(ValueError):
    """A parameter value is missing, unknown, of the wrong type or out of bounds."""


@dataclass(frozen=True)
class Parameter:
    name: str
    unit: str
    description: str
    default: Any = None            # None: required
    lower: float = -math.inf
    upper: float = math.inf
    kind: str = "float"            # float | vec3 | vec | choice | str
    choices: tuple[str, ...] = ()
    length: int = 0                # for kind == "vec": required length (0 = any)
    # the value at which what it measures is not there at all (a load set down: 0 kg), where that is an
    # everyday state whatever a spec's range says; None where the thing cannot be absent (a supply)
    absent: float | None = None

    def validate(self, value: Any, where: str) -> Any:
        """Return ``value`` converted to its kind, or raise :class:`ParameterError` naming ``where``."""
        label = f"{where}.{self.name}" if where else self.name
        if self.default is not None and not isinstance(self.default, (int, float)) and value == self.default:
            return self.default    # a keyword default ('auto', an unset vector) written out explicitly
        if isinstance(self.default, tuple) and isinstance(value, list) and tuple(value) == self.default:
            return self.default
        if self.kind == "float":
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                try:
                    value = float(value)
                except (TypeError, ValueError):
                    raise ParameterError(f"{label}: expected a number ({self.unit}), got {value!r}") from None
            value = float(value)
            if not math.isfinite(value):
                raise ParameterError(f"{label}: must be finite, got {value!r}")
            if not self.lower <= value <= self.upper:
                raise ParameterError(
                    f"{label}: {value:g} {self.unit} is outside [{self.lower:g}, {self.upper:g}]"
                )
            return value
        if self.kind in ("vec3", "vec"):
            n = 3 if self.kind == "vec3" else self.length
            if not isinstance(value, (list, tuple)) or (n and len(value) != n):
                raise ParameterError(f"{label}: expected a list of {n or 'some'} numbers ({self.unit}), got {value!r}")
            out = []
            for v in value:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
                    raise ParameterError(f"{label}: expected finite numbers, got {value!r}")
                out.append(float(v))
            return tuple(out)
        if self.kind == "choice":
            if value not in self.choices:
                raise ParameterError(f"{label}: expected one of {', '.join(self.choices)}, got {value!r}")
            return value
        if self.kind == "str":
            if not isinstance(value, str):
                raise ParameterError(f"{label}: expected text, got {value!r}")
            return value
        raise AssertionError(self.kind)

    def describe(self) -> dict:
        d = {"name": self.name, "unit": self.unit, "description": self.description, "default": self.default}
        if self.kind == "float":
            d["lower"] = None if math.isinf(self.lower) else self.lower
            d["upper"] = None if math.isinf(self.upper) else self.upper
        else:
            d["kind"] = self.kind
            if self.choices:
                d["choices"] = list(self.choices)
        return d


class Component:
    """A physical part with named parameters (values from the robot spec) and a citation.

    Subclasses set ``section`` (its table in the spec), ``PARAMETERS``, ``citation`` and put the
    equations they implement in their docstring; the compiled equations live beside them as numba
    functions that the kernel calls.
    """

    section: ClassVar[str] = ""
    citation: ClassVar[str] = ""
    PARAMETERS: ClassVar[tuple[Parameter, ...]] = ()

    def __init__(self, values: dict | None = None, where: str = ""):
        values = dict(values or {})
        self.where = where or self.section
        known = {p.name: p for p in self.PARAMETERS}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ParameterError(
                f"{self.where}: unknown parameter(s) {', '.join(unknown)}; known: {', '.join(known)}"
            )
        self.values: dict[str, Any] = {}
        for p in self.PARAMETERS:
            if p.name in values:
                self.values[p.name] = p.validate(values[p.name], self.where)
            elif p.default is not None:
                self.values[p.name] = p.default
            else:
                raise ParameterError(f"{self.where}.{p.name}: required parameter missing ({p.unit}): {p.description}")

    def __getitem__(self, name: str):
        return self.values[name]

    def set(self, name: str, value) -> None:
        known = {p.name: p for p in self.PARAMETERS}
        if name not in known:
            raise ParameterError(f"{self.where}: unknown parameter {name!r}; known: {', '.join(known)}")
        self.values[name] = known[name].validate(value, self.where)

    @classmethod
    def describe(cls) -> dict:
        return {
            "section": cls.section,
            "description": (cls.__doc__ or "").strip().splitlines()[0],
            "citation": cls.citation,
            "parameters": [p.describe() for p in cls.PARAMETERS],
        }
