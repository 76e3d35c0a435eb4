"""Template knobs: the few numbers and choices a rig template is drawn from (``--set NAME=VALUE``).

Some knobs stand for a robot.toml key (``supply.pressure``, ``joints.<joint>.cylinder.bore``): setting
that key with ``--set`` sets the knob, so the values derived from it (relief pressure, dead volumes,
the [estimated] ranges) follow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any


class RigError(ValueError):
    """A template, knob, key or value given to ``hydrohil rig new`` is wrong (the message names it)."""


@dataclass(frozen=True)
class Knob:
    name: str
    unit: str
    description: str
    default: Any
    lower: float = -math.inf
    upper: float = math.inf
    choices: tuple[str, ...] = ()
    path: str = ""          # robot.toml key it stands for ('{joint}' = the joint's name), '' if none

    def parse(self, value: Any) -> Any:
        if self.choices:
            if value not in self.choices:
                raise RigError(f"{self.name}: expected one of {', '.join(self.choices)}, got {value!r}")
            return value
        if isinstance(self.default, str):
            text = str(value)
            if not text.replace("_", "").isalnum() or not text[0].isalpha():
                raise RigError(f"{self.name}: expected a name of letters, digits and _ (starting with a letter), got {value!r}")
            return text
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise RigError(f"{self.name}: expected a number ({self.unit}), got {value!r}") from None
        if not math.isfinite(v) or not self.lower <= v <= self.upper:
            from ..model.spec import Parameter, _unit_hint

            hint = _unit_hint(Parameter(self.name, self.unit, "", 0.0, self.lower, self.upper), v)
            raise RigError(f"{self.name}: {v:g} {self.unit} is outside [{self.lower:g}, {self.upper:g}] {self.unit}{hint}")
        return v

    def describe(self) -> str:
        rng = f"one of {', '.join(self.choices)}" if self.choices else (
            "text" if isinstance(self.default, str) else f"{self.lower:g} to {self.upper:g} {self.unit}")
        return f"{self.name} ({rng}; default {self.default}): {self.description}"


def common_knobs(joint: str, load: float, supply: float, rated_flow: float) -> list[Knob]:
    return [
        Knob("joint", "-", "name of the actuated joint (URDF joint and [joints.<name>])", joint),
        Knob("load_kg", "kg", "load carried (the payload effect)", load, 0.0, 5000.0,
             path="effects.payload.{joint}.mass"),
        Knob("supply_pressure", "Pa", "supply pressure", supply, 1e6, 4e7, path="supply.pressure"),
        Knob("rated_flow", "m^3/s", "valve flow per edge at the rated drop", rated_flow, 1e-6, 0.01,
             path="joints.{joint}.valve.rated_flow"),
    ]


TEMPLATE_KNOBS: dict[str, list[Knob]] = {
    "cylinder": common_knobs("lift", 100.0, 14e6, 2.0e-4) + [
        Knob("orientation", "-", "direction of travel: vertical (lifting against gravity), horizontal, or "
             "incline (give incline_deg)", "vertical", choices=("vertical", "horizontal", "incline")),
        Knob("incline_deg", "deg", "travel angle of the extending rod above horizontal (90 = vertical, extending lifts; -90 = a load "
             "hanging below the cylinder, lifted by retracting: the rod side carries it); implies orientation=incline",
             90.0, -90.0, 90.0),
        Knob("stroke", "m", "cylinder stroke = the slide's travel (joint limits 0..stroke)", 0.5, 0.02, 5.0),
        Knob("carriage_kg", "kg", "moving mass without the load (piston, rod, carriage)", 15.0, 0.1, 5000.0),
        Knob("bore", "m", "piston diameter", 0.05, 0.01, 0.5, path="joints.{joint}.cylinder.bore"),
        Knob("rod", "m", "rod diameter", 0.028, 0.005, 0.4, path="joints.{joint}.cylinder.rod_diameter"),
    ],
    "boom": common_knobs("boom", 40.0, 14e6, 3.3e-4) + [
        Knob("boom_length", "m", "pivot to the load's hook", 2.0, 0.2, 30.0),
        Knob("boom_kg", "kg", "boom mass without the load", 60.0, 0.5, 20000.0),
        Knob("pivot_height", "m", "height of the boom pivot (only drawn)", 1.2, 0.0, 20.0),
        Knob("bore", "m", "piston diameter", 0.05, 0.01, 0.5, path="joints.{joint}.cylinder.bore"),
        Knob("rod", "m", "rod diameter", 0.03, 0.005, 0.4, path="joints.{joint}.cylinder.rod_diameter"),
    ],
    "rotary": common_knobs("swing", 5.0, 14e6, 5.0e-5) + [
        Knob("axis", "-", "shaft axis: horizontal (the arm lifts against gravity) or vertical (a turntable)",
             "horizontal", choices=("horizontal", "vertical")),
        Knob("actuator", "-", "vane (limited-angle rotary actuator) or motor (hydraulic motor)", "vane",
             choices=("vane", "motor"), path="joints.{joint}.rotary.type"),
        Knob("arm_length", "m", "shaft to the load", 0.6, 0.05, 10.0),
        Knob("arm_kg", "kg", "arm mass without the load", 10.0, 0.1, 5000.0),
        Knob("displacement", "m^3/rad", "actuator displacement per radian", 2.0e-5, 1e-8, 1e-2,
             path="joints.{joint}.rotary.displacement"),
    ],
}
