"""URDF -> kinematic tree arrays for the rigid-body kernel.

The simulator, the Pinocchio oracle in the tests and the 3D viewer all read the same URDF, so the
robot geometry has one source of truth. Supported joints: ``revolute``, ``prismatic`` and ``fixed``
(``continuous`` is treated as revolute without limits). Bodies joined by fixed joints are merged into
their moving parent, as Pinocchio does.

Conventions: body ``i`` is the child of moving joint ``i``; its frame is the joint frame (URDF joint
origin), then rotated by ``q_i`` (rad) about the joint axis for a revolute joint, or translated by
``q_i`` (m) along the axis for a prismatic one (``jtype[i]``: :data:`REVOLUTE` or :data:`PRISMATIC`).
Joints are ordered so that every parent comes before its children (``parent[i] < i``; ``-1`` is the
fixed root/world body).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


REVOLUTE = 0   #: ``KinematicTree.jtype`` of a revolute (or continuous) joint: q in rad
PRISMATIC = 1  #: ``KinematicTree.jtype`` of a prismatic joint: q in m

_JTYPE = {"revolute": REVOLUTE, "continuous": REVOLUTE, "prismatic": PRISMATIC}


class UrdfError(ValueError):
    """The URDF cannot be turned into a kinematic tree (names the element at fault)."""


def rpy_to_matrix(rpy) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(yaw) @ Ry(pitch) @ Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _vec(text: str | None, default=(0.0, 0.0, 0.0)) -> np.ndarray:
    if text is None:
        return np.array(default, dtype=float)
    vals = [float(v) for v in text.split()]
    if len(vals) != 3:
        raise UrdfError(f"expected 3 numbers, got {text!r}")
    return np.array(vals)


def _origin(elem) -> tuple[np.ndarray, np.ndarray]:
    o = elem.find("origin") if elem is not None else None
    if o is None:
        return np.eye(3), np.zeros(3)
    return rpy_to_matrix(_vec(o.get("rpy"))), _vec(o.get("xyz"))


@dataclass
class _Link:
    name: str
    mass: float = 0.0
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    inertia: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))  # about COM, link frame


@dataclass
class _Joint:
    name: str
    type: str
    parent: str
    child: str
    R: np.ndarray
    p: np.ndarray
    axis: np.ndarray
    lower: float
    upper: float
    damping: float


@dataclass
class KinematicTree:
    """Arrays describing the moving bodies of a robot (SI units, root/world frame z up)."""

    name: str
    dof_names: list[str]            # moving joint names, topological order
    link_names: list[str]           # child link of each moving joint
    parent: np.ndarray              # int64 [n], -1 = fixed root body
    R_tree: np.ndarray              # [n,3,3] joint frame orientation in parent body frame
    p_tree: np.ndarray              # [n,3]   joint frame origin in parent body frame (m)
    axis: np.ndarray                # [n,3]   unit joint axis in joint frame (rotation or translation)
    mass: np.ndarray                # [n]     body mass (kg), fixed children merged
    com: np.ndarray                 # [n,3]   centre of mass in body frame (m)
    inertia: np.ndarray             # [n,3,3] inertia about the COM in body frame (kg m^2)
    lower: np.ndarray               # [n] joint limit (rad; m for prismatic), -inf if none
    upper: np.ndarray               # [n] joint limit (rad; m for prismatic), +inf if none
    damping: np.ndarray             # [n] viscous joint damping (N m s/rad; N s/m for prismatic)
    root_link: str
    # every URDF link -> (body index or -1 for the root, R, p) of its frame in that body's frame
    link_frames: dict[str, tuple[int, np.ndarray, np.ndarray]]
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    jtype: np.ndarray | None = None  # int64 [n]: REVOLUTE or PRISMATIC; None means all revolute

    def __post_init__(self) -> None:
        if self.jtype is None:
            self.jtype = np.full(len(self.dof_names), REVOLUTE, dtype=np.int64)
        self.jtype = np.ascontiguousarray(self.jtype, dtype=np.int64)

    @property
    def n(self) -> int:
        return len(self.dof_names)

    def is_prismatic(self, dof: int | str) -> bool:
        """Whether a joint (index or name) translates (q in m) rather than rotates (q in rad)."""
        i = self.index(dof) if isinstance(dof, str) else dof
        return bool(self.jtype[i] == PRISMATIC)

    def index(self, dof: str) -> int:
        try:
            return self.dof_names.index(dof)
        except ValueError:
            raise KeyError(f"unknown joint {dof!r}; joints: {', '.join(self.dof_names)}") from None


def _parse_link(el) -> _Link:
    link = _Link(el.get("name"))
    inert = el.find("inertial")
    if inert is not None:
        R, p = _origin(inert)
        m = inert.find("mass")
        link.mass = float(m.get("value")) if m is not None else 0.0
        i = inert.find("inertia")
        if i is not None:
            g = lambda k: float(i.get(k, "0"))  # noqa: E731
            I = np.array(
                [
                    [g("ixx"), g("ixy"), g("ixz")],
                    [g("ixy"), g("iyy"), g("iyz")],
                    [g("ixz"), g("iyz"), g("izz")],
                ]
            )
        else:
            I = np.zeros((3, 3))
        link.com = p
        link.inertia = R @ I @ R.T
    return link


def _parse_joint(el) -> _Joint:
    name = el.get("name")
    jtype = el.get("type")
    if jtype not in ("revolute", "continuous", "prismatic", "fixed"):
        raise UrdfError(f"joint {name!r}: type {jtype!r} is not supported (revolute, continuous, prismatic, fixed)")
    R, p = _origin(el)
    axis = _vec(el.find("axis").get("xyz") if el.find("axis") is not None else None, (1.0, 0.0, 0.0))
    if jtype != "fixed":
        nrm = np.linalg.norm(axis)
        if nrm < 1e-12:
            raise UrdfError(f"joint {name!r}: zero axis")
        axis = axis / nrm
    lower, upper = -np.inf, np.inf
    lim = el.find("limit")
    if jtype in ("revolute", "prismatic") and lim is not None:
        lower = float(lim.get("lower", "-inf"))
        upper = float(lim.get("upper", "inf"))
        if not lower < upper:
            raise UrdfError(f"joint {name!r}: limit lower {lower} must be below upper {upper}")
    dyn = el.find("dynamics")
    damping = float(dyn.get("damping", "0")) if dyn is not None else 0.0
    return _Joint(name, jtype, el.find("parent").get("link"), el.find("child").get("link"), R, p, axis, lower, upper, damping)


def load_urdf(source: str | Path, *, from_string: bool = False) -> KinematicTree:
    """Parse a URDF file (or string) into a :class:`KinematicTree`."""
    try:
        root = ET.fromstring(source) if from_string else ET.parse(source).getroot()
    except ET.ParseError as exc:
        raise UrdfError(f"malformed URDF: {exc}") from exc
    links = {el.get("name"): _parse_link(el) for el in root.findall("link")}
    joints = [_parse_joint(el) for el in root.findall("joint")]
    children: dict[str, list[_Joint]] = {}
    child_links = set()
    for j in joints:
        for lk in (j.parent, j.child):
            if lk not in links:
                raise UrdfError(f"joint {j.name!r} refers to unknown link {lk!r}")
        if j.child in child_links:
            raise UrdfError(f"link {j.child!r} has two parent joints (not a tree)")
        child_links.add(j.child)
        children.setdefault(j.parent, []).append(j)
    roots = [n for n in links if n not in child_links]
    if len(roots) != 1:
        raise UrdfError(f"URDF must have exactly one root link, found {roots}")
    root_link = roots[0]

    dof_names, link_names, parent = [], [], []
    R_tree, p_tree, axis, lower, upper, damping, jtypes = [], [], [], [], [], [], []
    mass, com, inertia = [], [], []
    link_frames: dict[str, tuple[int, np.ndarray, np.ndarray]] = {root_link: (-1, np.eye(3), np.zeros(3))}
    # body accumulators: (mass, first moment, inertia about body origin) in body frame
    acc: list[list] = []

    def add_mass(body: int, lk: _Link, R: np.ndarray, p: np.ndarray) -> None:
        if body < 0 or lk.mass == 0.0 and not lk.inertia.any():
            return
        c = R @ lk.com + p
        Ic = R @ lk.inertia @ R.T
        acc[body][0] += lk.mass
        acc[body][1] += lk.mass * c
        acc[body][2] += Ic + lk.mass * (np.dot(c, c) * np.eye(3) - np.outer(c, c))

    def visit(link: str, body: int, R: np.ndarray, p: np.ndarray) -> None:
        for j in children.get(link, []):
            Rj, pj = R @ j.R, R @ j.p + p  # joint frame in current body frame
            if j.type == "fixed":
                link_frames[j.child] = (body, Rj, pj)
                add_mass(body, links[j.child], Rj, pj)
                visit(j.child, body, Rj, pj)
            else:
                idx = len(dof_names)
                dof_names.append(j.name)
                link_names.append(j.child)
                parent.append(body)
                R_tree.append(Rj)
                p_tree.append(pj)
                axis.append(j.axis)
                lower.append(j.lower)
                upper.append(j.upper)
                damping.append(j.damping)
                jtypes.append(_JTYPE[j.type])
                acc.append([0.0, np.zeros(3), np.zeros((3, 3))])
                link_frames[j.child] = (idx, np.eye(3), np.zeros(3))
                add_mass(idx, links[j.child], np.eye(3), np.zeros(3))
                visit(j.child, idx, np.eye(3), np.zeros(3))

    visit(root_link, -1, np.eye(3), np.zeros(3))
    for m_, h, I_o in acc:
        c = h / m_ if m_ > 0 else np.zeros(3)
        mass.append(m_)
        com.append(c)
        inertia.append(I_o - m_ * (np.dot(c, c) * np.eye(3) - np.outer(c, c)))
    n = len(dof_names)
    if n == 0:
        raise UrdfError("URDF has no moving joints")
    for i, m_ in enumerate(mass):
        if m_ <= 0.0:
            raise UrdfError(f"body of joint {dof_names[i]!r} has no mass")
    return KinematicTree(
        name=root.get("name", "robot"),
        dof_names=dof_names,
        link_names=link_names,
        parent=np.array(parent, dtype=np.int64),
        R_tree=np.array(R_tree).reshape(n, 3, 3),
        p_tree=np.array(p_tree).reshape(n, 3),
        axis=np.array(axis).reshape(n, 3),
        mass=np.array(mass),
        com=np.array(com).reshape(n, 3),
        inertia=np.array(inertia).reshape(n, 3, 3),
        lower=np.array(lower),
        upper=np.array(upper),
        damping=np.array(damping),
        root_link=root_link,
        link_frames=link_frames,
        jtype=np.array(jtypes, dtype=np.int64),
    )
