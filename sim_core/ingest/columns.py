"""``--column NAME=SOURCE[:UNIT]``: which file column becomes which dataset column of a robot."""

from __future__ import annotations

from dataclasses import dataclass

from .units import SENSOR_VOLTS, UNITS

REVOLUTE, PRISMATIC = 0, 1


@dataclass(frozen=True)
class ColumnMap:
    """One ``--column``: dataset column ``name`` from file column ``source`` in ``unit``."""

    name: str
    source: str | int          # header name, or 0-based column index
    unit: str | None           # None: the dataset's SI unit
    text: str                  # the option as given (for messages)

    @property
    def source_label(self) -> str:
        return f"column {self.source}" if isinstance(self.source, int) else f"header {self.source!r}"


def _looks_like_unit(text: str) -> bool:
    t = text.strip().lower()
    return t.startswith("*") or t == SENSOR_VOLTS or any(t == u.lower() for k in UNITS.values() for u in k)


def parse_column(text: str) -> ColumnMap:
    """'q_boom=2:sensor_volts' -> ColumnMap('q_boom', 2, 'sensor_volts'). A header name may hold ':'
    as long as what follows the last ':' is not a unit."""
    name, eq, rest = text.partition("=")
    name, rest = name.strip(), rest.strip()
    if not eq or not name or not rest:
        raise ValueError(f"--column {text!r}: expected NAME=SOURCE[:UNIT], e.g. q_j2=3:deg or time=t_ms:ms")
    source, unit = rest, None
    head, colon, tail = rest.rpartition(":")
    if colon and _looks_like_unit(tail):
        source, unit = head.strip(), tail.strip()
    elif colon and (head.strip().isdigit() or tail.strip().startswith("*")):
        raise ValueError(f"--column {text!r}: {tail.strip()!r} is not a unit (s, ms; V, mV; m, mm, rad, deg; "
                         f"Pa, kPa, bar, MPa, psi; sensor_volts; *SCALE+OFFSET)")
    if not source:
        raise ValueError(f"--column {text!r}: no SOURCE (a header name or a 0-based column index)")
    src: str | int = int(source) if source.isdigit() else source
    return ColumnMap(name, src, unit, text)


def joint_type(spec, joint: str) -> int:
    """REVOLUTE or PRISMATIC; a kinematic tree without ``jtype`` is all revolute."""
    tree = spec.tree
    jtype = getattr(tree, "jtype", None)
    if jtype is None:
        return REVOLUTE
    return int(jtype[tree.index(spec.joint(joint).dof)])


def column_kind(name: str, spec) -> tuple[str, str | None]:
    """(kind, joint) of dataset column ``name`` on ``spec``; ValueError for a name the dataset has not."""
    joints = spec.joint_names
    if name == "time":
        return "time", None
    for prefix in ("u_", "q_"):
        if name.startswith(prefix) and name[2:] in joints:
            j = name[2:]
            if prefix == "u_":
                return "command", j
            return ("position" if joint_type(spec, j) == PRISMATIC else "angle"), j
    if name.startswith("p_") and name[-2:] in ("_a", "_b") and name[2:-2] in joints:
        return "pressure", name[2:-2]
    hint = ""
    for prefix in ("u_", "q_", "p_"):
        if name.startswith(prefix):
            hint = f"; joints of {spec.name}: {', '.join(joints)}"
    raise ValueError(f"--column {name}=...: {name!r} is not a dataset column of {spec.name} (expected time, "
                     f"u_<joint>, q_<joint>, p_<joint>_a or p_<joint>_b){hint}")


def dataset_order(names, spec) -> list[str]:
    """Dataset columns in the order ``hydrohil simulate`` writes them: time, u_, q_, p_a/p_b per joint."""
    order = ["time"] + [f"u_{j}" for j in spec.joint_names] + [f"q_{j}" for j in spec.joint_names]
    for j in spec.joint_names:
        order += [f"p_{j}_a", f"p_{j}_b"]
    present = set(names)
    return [c for c in order if c in present]
