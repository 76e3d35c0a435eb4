"""One robot described for people and programs (``hydrohil robots --robot R --json``): its joints
with their type and the units of q, actuators, sensors, limits, switched-on effects and every
parameter with its unit."""

from __future__ import annotations

import math
from typing import Any

from ..effects import EFFECTS
from .spec import GLOBAL_SECTIONS, ROBOTS_DIR, RobotSpec, estimated_unit, joint_unit


def _value(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return list(v) if isinstance(v, tuple) else v


def _params(comp, prismatic: bool, joint_referred: bool) -> dict:
    return {p.name: {"value": _value(comp.values[p.name]), "unit": joint_unit(p.unit, prismatic, joint_referred)}
            for p in comp.PARAMETERS}


def describe_robot(spec: RobotSpec) -> dict:
    tree = spec.tree
    joints = []
    for j in spec.joints:
        i = tree.index(j.dof)
        prismatic = bool(tree.is_prismatic(i))
        qu = "m" if prismatic else "rad"
        sensor = None
        if j.sensed:
            s = j.components["sensor"]
            sensor = {"model": f"position = A * volts + B ({qu})", "A": s["A"], "A_unit": f"{qu}/V",
                      "B": s["B"], "B_unit": qu, "noise_V": s["noise"], "range_V": list(s["range"])}
        act = {"kind": j.actuator_label}
        if j.kind == "cylinder":
            cyl = j.components["cylinder"]
            act.update(linkage=cyl["linkage"], bore_m=cyl["bore"], rod_diameter_m=cyl["rod_diameter"])
        else:
            act.update(type=j.components["rotary"]["type"], displacement_m3_per_rad=j.components["rotary"]["displacement"])
        joints.append({
            "name": j.name,
            "urdf_joint": j.dof,
            "type": "prismatic" if prismatic else "revolute",
            "q_unit": qu,
            "qd_unit": f"{qu}/s",
            "actuator": act,
            "sensed": j.sensed,
            "sensor": sensor,
            "limits": [_value(float(tree.lower[i])), _value(float(tree.upper[i]))],
            "command_voltage_range": list(j.command_range),
            "initial_position": j.settings["initial_position"],
            "effects": [{"name": e.name, "params": dict(e.params),
                         "units": {k: joint_unit(next((p.unit for p in EFFECTS[e.name].PARAMETERS if p.name == k), ""),
                                                 prismatic) for k in e.params}}
                        for e in spec.effects if e.joint == j.name],
            "parameters": {
                **{k: v for k, v in _params(j.settings, prismatic, True).items() if k == "initial_position"},
                **{sec: _params(comp, prismatic, sec == "sensor") for sec, comp in j.components.items()},
            },
        })
    passive = []
    for d in spec.passive:
        i = tree.index(d)
        passive.append({"name": d, "type": "prismatic" if tree.is_prismatic(i) else "revolute",
                        "q_unit": "m" if tree.is_prismatic(i) else "rad"})
    source = spec.source
    return {
        "name": spec.name,
        "description": spec.description,
        "reference": spec.reference,
        "source": str(source) if source else None,
        "builtin": bool(source and source.parent.parent == ROBOTS_DIR),
        "urdf": str(spec.urdf_path),
        "joints": joints,
        "passive_joints": passive,
        "global_effects": [{"name": e.name, "params": dict(e.params)} for e in spec.effects if e.joint is None],
        **{sec: _params(getattr(spec, sec), False, False) for sec in GLOBAL_SECTIONS},
        "estimated": {k: list(v) for k, v in spec.estimated.items()},
        "estimated_units": {k: estimated_unit(spec, k) for k in spec.estimated},
    }
