"""The FMU's interface, derived from a robot spec: inputs, outputs and parameters with units.

* inputs ``u_<joint>`` (V): the command of each actuated joint, held over a communication step;
* outputs ``q_<joint>`` (rad, or m for a prismatic joint): the measured position of each sensed
  joint through its sensor model (gain, offset, noise, ADC), the dataset's ``q_`` columns;
  ``qd_<joint>`` (rad/s or m/s): the true velocity of every moving URDF joint (actuated joints by
  their joint name, passive ones by their URDF name); ``p_<joint>_a`` / ``p_<joint>_b`` (Pa): the
  chamber pressures;
* parameters: every number of the spec (each float path of :meth:`RobotSpec.parameters`, units from
  the component declarations) and ``seed``, the sensor-noise seed of ``hydrohil simulate --seed``.

Names follow :mod:`.fmi_names`; units :mod:`.units`. The same table is used to write the
modelDescription.xml and, inside the FMU, to serve the variables, so the two cannot disagree.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..model.spec import GLOBAL_SECTIONS
from .fmi_names import FmiNameError, path_name, signal_name
from .units import for_joint_type

SEED = "seed"


@dataclass(frozen=True)
class Variable:
    name: str            # FMI name
    causality: str       # input | output | parameter
    unit: str            # project unit string ('' = dimensionless)
    description: str
    kind: str = ""       # outputs: angle | velocity | p_a | p_b; inputs: command; parameters: path | seed
    index: int = -1      # actuator index (command, angle, pressures) or URDF dof index (velocity)
    path: str = ""       # parameter path


def _prismatic(spec, dof: str) -> bool:
    return bool(spec.tree.is_prismatic(spec.tree.index(dof)))


def parameter_entries(spec):
    """(path, Parameter declaration, prismatic) of every float parameter of ``spec``."""
    out = []
    for sec in GLOBAL_SECTIONS:
        comp = getattr(spec, sec)
        out += [(f"{sec}.{p.name}", p, False) for p in comp.PARAMETERS]
    for j in spec.joints:
        pri = _prismatic(spec, j.dof)
        out += [(f"joints.{j.name}.{p.name}", p, pri) for p in j.settings.PARAMETERS]
        for sec, comp in j.components.items():
            out += [(f"joints.{j.name}.{sec}.{p.name}", p, pri) for p in comp.PARAMETERS]
    for d, s in spec.passive.items():
        pri = _prismatic(spec, d)
        out += [(f"passive.{d}.{p.name}", p, pri) for p in s.PARAMETERS]
    floats = {k for k, v in spec.parameters().items() if isinstance(v, float)}
    out = [e for e in out if e[1].kind == "float" and e[0] in floats]
    missing = floats - {e[0] for e in out}
    if missing:  # a parameter path the traversal above does not know: the two must be extended together
        raise AssertionError(f"no declaration found for parameter(s) {', '.join(sorted(missing))}")
    return out


def interface(spec) -> list[Variable]:
    """Every FMU variable of ``spec``, in value-reference order; names are checked unique."""
    tree = spec.tree
    vs: list[Variable] = []
    for a, j in enumerate(spec.joints):
        lo, hi = j.command_range
        vs.append(Variable(signal_name("u_", j.name), "input", "V",
                           f"command voltage of joint {j.name}, held over each communication step; "
                           f"clamped to [{lo:g}, {hi:g}] V like the cFP output", "command", a))
    for a, j in enumerate(spec.joints):
        if j.sensed:
            u = "m" if _prismatic(spec, j.dof) else "rad"
            vs.append(Variable(signal_name("q_", j.name), "output", u,
                               f"measured position of joint {j.name} through its sensor model ({u})", "angle", a))
    actuated = {j.dof: j.name for j in spec.joints}
    for i, dof in enumerate(tree.dof_names):
        u = "m/s" if _prismatic(spec, dof) else "rad/s"
        label = actuated.get(dof, dof)
        what = f"joint {label}" if dof in actuated else f"passive URDF joint {dof}"
        vs.append(Variable(signal_name("qd_", label), "output", u, f"true velocity of {what} ({u})", "velocity", i))
    for a, j in enumerate(spec.joints):
        for ch in ("a", "b"):
            vs.append(Variable(signal_name("p_", j.name, f"_{ch}"), "output", "Pa",
                               f"pressure in chamber {ch.upper()} of joint {j.name} (Pa)", f"p_{ch}", a))
    for path, p, pri in parameter_entries(spec):
        unit = for_joint_type(p.unit, pri)
        vs.append(Variable(path_name(path), "parameter", unit, f"{p.description} ({unit})", "path", path=path))
    vs.append(Variable(SEED, "parameter", "", "seed of the sensor noise (hydrohil simulate --seed)", "seed"))
    seen: dict[str, Variable] = {}
    for v in vs:
        if v.name in seen:
            raise FmiNameError(f"two FMU variables would be named {v.name!r} ({seen[v.name].description}; "
                               f"{v.description}): rename a joint")
        seen[v.name] = v
    return vs
