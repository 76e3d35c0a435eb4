"""Symbolic equations of motion ``M(q) qdd + C(q, qd) qd + g(q) = tau`` of a kinematic tree.

The same tree the simulator integrates (:class:`sim_core.model.urdf.KinematicTree`: fixed joints
merged, the same frames) is run through the recursive algorithms in body coordinates, each step
named in a straight-line :class:`~sim_core.symbolic.program.Program`, so the derivation is linear in
the number of bodies (MARS-ND's 14 joints take seconds, not the hours of a Lagrangian expansion):

* ``M(q)``: composite rigid body algorithm (Walker & Orin 1982; Featherstone 2008, table 6.2);
* ``c(q, qd) = C(q, qd) qd``: recursive Newton-Euler (Luh, Walker & Paul 1980) with ``qdd = 0``
  and no gravity;
* ``g(q)``: the same with ``qd = qdd = 0`` and the root accelerating at ``-gravity``.

Body ``i``'s frame is its joint frame after the motion: rotated by ``q_i`` (rad) about the axis for
a revolute joint, shifted by ``q_i`` (m) along it for a prismatic one. Geometry and inertia enter as
numbers; rounding residue of the URDF's rotations (|x| < 1e-14, or within 1e-14 of +-1 in a
rotation) is snapped to the exact value, so axes along x, y or z and zero offsets cancel terms
exactly. Units: SI; ``tau`` in N m for a revolute joint and N for a prismatic one.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass

import numpy as np
import sympy as sp

from ..model.urdf import PRISMATIC, KinematicTree
from .program import Block, Program, extract

_SNAP = 1e-14
_TRIG = re.compile(r"^[sc]\d+$")


def _num(x: float, scale: float = 1.0, unit: bool = False) -> sp.Expr:
    """A URDF number as sympy: 0 below ``_SNAP * scale``, +-1 (rotations, ``unit``) or an integer
    when exact, else a 17-digit float (round-trips the double)."""
    x = float(x)
    if abs(x) < _SNAP * scale:
        return sp.Integer(0)
    if unit and abs(abs(x) - 1.0) < _SNAP:
        return sp.Integer(1 if x > 0 else -1)
    if x == round(x) and abs(x) < 2**53:
        return sp.Integer(int(x))
    return sp.Float(x, 17)


@dataclass
class EquationsOfMotion:
    """``M(q) qdd + c(q, qd) + g(q) = tau`` as three straight-line programs (inputs ``q``, ``qd``)."""

    name: str
    dof_names: list[str]
    joint_types: list[str]          # "revolute" or "prismatic", per dof
    gravity: np.ndarray             # m/s^2, root frame
    q: list[sp.Symbol]              # rad or m
    qd: list[sp.Symbol]             # rad/s or m/s
    mass_matrix: Block              # outputs: M row-major, n*n (symmetric)
    coriolis: Block                 # outputs: c = C(q, qd) qd, n
    gravity_torque: Block           # outputs: g(q), n
    derive_seconds: float

    @property
    def n(self) -> int:
        return len(self.dof_names)


class _Joint:
    """Symbolic transform between a body and its parent (``to_child``/``to_parent`` rotate a vector
    of the parent's / the body's frame into the other one)."""

    def __init__(self, prog: Program, tree: KinematicTree, i: int, q: sp.Symbol):
        self.prog = prog
        self.prismatic = bool(tree.jtype[i] == PRISMATIC)
        self.R = [[_num(tree.R_tree[i, r, c], unit=True) for c in range(3)] for r in range(3)]
        self.z = [_num(v, unit=True) for v in tree.axis[i]]
        p = [_num(v) for v in tree.p_tree[i]]
        if self.prismatic:
            self.rot = None
            # origin in the parent frame: p_tree + R_tree z q
            self.r = [prog.let(p[k] + sum(self.R[k][m] * self.z[m] for m in range(3)) * q) for k in range(3)]
        else:
            c = prog.let(sp.cos(q), name=f"c{i}")
            s = prog.let(sp.sin(q), name=f"s{i}")
            x, y, z = self.z
            t = 1 - c
            rot = [[t * x * x + c, t * x * y - s * z, t * x * z + s * y],
                   [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
                   [t * x * z - s * y, t * y * z + s * x, t * z * z + c]]
            self.rot = [[prog.let(sp.expand(e)) for e in row] for row in rot]
            self.r = p

    def to_child(self, v):
        u = _matvec(self.prog, self.R, v, transpose=True)
        return u if self.rot is None else _matvec(self.prog, self.rot, u, transpose=True)

    def to_parent(self, v):
        u = v if self.rot is None else _matvec(self.prog, self.rot, v)
        return _matvec(self.prog, self.R, u)


def _cross(prog: Program, a, b):
    return [prog.let(a[1] * b[2] - a[2] * b[1]), prog.let(a[2] * b[0] - a[0] * b[2]), prog.let(a[0] * b[1] - a[1] * b[0])]


def _add(prog: Program, *vs):
    return [prog.let(sum(v[k] for v in vs)) for k in range(3)]


def _scale(prog: Program, s, v):
    return [prog.let(s * x) for x in v]


def _dot(prog: Program, a, b):
    return prog.let(sum(a[k] * b[k] for k in range(3)))


def _matvec(prog: Program, A, v, transpose=False):
    """``A v`` (or ``A^T v``) for a 3x3 ``A`` given as rows."""
    if transpose:
        return [prog.let(sum(A[m][k] * v[m] for m in range(3))) for k in range(3)]
    return [prog.let(sum(A[k][m] * v[m] for m in range(3))) for k in range(3)]


def _body_inertia(tree: KinematicTree, i: int):
    """Mass (kg), first moment ``m c`` (kg m) and inertia about the body origin (kg m^2), body frame."""
    m = float(tree.mass[i])
    c = tree.com[i]
    I_o = tree.inertia[i] + m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    scale = float(np.abs(I_o).max())
    return (_num(m), [_num(m * x, scale=max(m, 1e-300)) for x in c],
            [[_num(I_o[r, k], scale=scale) for k in range(3)] for r in range(3)])


def _rnea(prog: Program, tree: KinematicTree, joints: list[_Joint], qd, qdd, a_root):
    """Joint forces of the recursive Newton-Euler algorithm in body coordinates."""
    n = tree.n
    zero = [sp.Integer(0)] * 3
    w, al, a, f, nm = [None] * n, [None] * n, [None] * n, [None] * n, [None] * n
    for i in range(n):
        J, p = joints[i], int(tree.parent[i])
        if p < 0:
            wp, alp, ao = zero, zero, J.to_child(a_root)
        else:
            wp, alp = J.to_child(w[p]), J.to_child(al[p])
            r = J.r
            ao = J.to_child(_add(prog, a[p], _cross(prog, al[p], r), _cross(prog, w[p], _cross(prog, w[p], r))))
        zqd = _scale(prog, qd[i], J.z)
        if J.prismatic:
            w[i], al[i] = wp, alp
            a[i] = _add(prog, ao, _scale(prog, qdd[i], J.z), _scale(prog, 2, _cross(prog, wp, zqd)))
        else:
            w[i] = _add(prog, wp, zqd)
            al[i] = _add(prog, alp, _scale(prog, qdd[i], J.z), _cross(prog, wp, zqd))
            a[i] = ao
        m, h, I = _body_inertia(tree, i)
        f[i] = _add(prog, _scale(prog, m, a[i]), _cross(prog, al[i], h), _cross(prog, w[i], _cross(prog, w[i], h)))
        nm[i] = _add(prog, _matvec(prog, I, al[i]), _cross(prog, w[i], _matvec(prog, I, w[i])), _cross(prog, h, a[i]))
    tau = [None] * n
    for i in range(n - 1, -1, -1):
        J, p = joints[i], int(tree.parent[i])
        tau[i] = _dot(prog, J.z, f[i] if J.prismatic else nm[i])
        if p >= 0:
            fp = J.to_parent(f[i])
            f[p] = _add(prog, f[p], fp)
            nm[p] = _add(prog, nm[p], J.to_parent(nm[i]), _cross(prog, J.r, fp))
    return tau


def _crba(prog: Program, tree: KinematicTree, joints: list[_Joint]):
    """Joint-space inertia matrix (row-major list) of the composite rigid body algorithm."""
    n = tree.n
    comp = [_body_inertia(tree, i) for i in range(n)]
    for i in range(n - 1, -1, -1):
        p = int(tree.parent[i])
        if p < 0:
            continue
        J = joints[i]
        m, h, I = comp[i]
        r = J.r
        hp = J.to_parent(h)
        # E I E^T, then the parallel-axis shift from the body origin to the parent's origin
        cols = [J.to_parent([I[0][k], I[1][k], I[2][k]]) for k in range(3)]  # E I, by columns
        EI = [[cols[k][rr] for k in range(3)] for rr in range(3)]
        Ip = [J.to_parent(EI[rr]) for rr in range(3)]  # (E I E^T)[rr, :] = E (E I)[rr, :]^T
        for a in range(3):
            for b in range(a):
                Ip[a][b] = Ip[b][a]  # symmetric: the lower triangle repeats the upper one
        rr_ = sum(x * x for x in r)
        rh = sum(r[k] * hp[k] for k in range(3))
        mp, hpar, Ipar = comp[p]
        new_I = [[prog.let(Ipar[a][b] + Ip[a][b] + m * ((rr_ if a == b else 0) - r[a] * r[b])
                           + (2 * rh if a == b else 0) - r[a] * hp[b] - hp[a] * r[b]) for b in range(3)] for a in range(3)]
        comp[p] = (mp + m, [prog.let(hpar[k] + m * r[k] + hp[k]) for k in range(3)], new_I)
    M = [[sp.Integer(0)] * n for _ in range(n)]
    for j in range(n):
        J = joints[j]
        m, h, I = comp[j]
        if J.prismatic:
            nv, fv = _cross(prog, h, J.z), _scale(prog, m, J.z)
        else:
            nv, fv = _matvec(prog, I, J.z), _cross(prog, J.z, h)
        M[j][j] = _dot(prog, J.z, fv if J.prismatic else nv)
        i = j
        while tree.parent[i] >= 0:
            Ji = joints[i]
            fv = Ji.to_parent(fv)
            nv = _add(prog, Ji.to_parent(nv), _cross(prog, Ji.r, fv))
            i = int(tree.parent[i])
            M[i][j] = M[j][i] = _dot(prog, joints[i].z, fv if joints[i].prismatic else nv)
    return [M[r][c] for r in range(n) for c in range(n)]


def _renumber(blocks: list[Block]) -> list[Block]:
    """Intermediate quantities renamed x0, x1, ... in order of first definition over the blocks
    (sin/cos of the joints keep their names s<i>, c<i>); a name means the same quantity in every
    block."""
    names: dict[sp.Symbol, sp.Symbol] = {}
    for b in blocks:
        for sym, _ in b.assignments:
            if sym not in names and not _TRIG.match(sym.name):
                names[sym] = sp.Symbol(f"x{len(names)}", real=True)
    # two passes through a temporary name: an old x7 may become x3 while an old x3 is still in use
    tmp = {old: sp.Dummy() for old in names}
    final = {tmp[old]: new for old, new in names.items()}

    def rename(e):
        return e.xreplace(tmp).xreplace(final)

    return [Block([(rename(sym), rename(e)) for sym, e in b.assignments], [rename(e) for e in b.outputs]) for b in blocks]


def derive_equations(tree: KinematicTree, cse: bool = True) -> EquationsOfMotion:
    """Derive ``M(q)``, ``c(q, qd) = C(q, qd) qd`` and ``g(q)`` of ``tree`` (SI units)."""
    t0 = time.perf_counter()
    n = tree.n
    q = [sp.Symbol(f"q{i}", real=True) for i in range(n)]
    qd = [sp.Symbol(f"qd{i}", real=True) for i in range(n)]
    prog = Program()
    joints = [_Joint(prog, tree, i, q[i]) for i in range(n)]
    M = _crba(prog, tree, joints)
    zero = [sp.Integer(0)] * n
    c = _rnea(prog, tree, joints, qd, zero, [sp.Integer(0)] * 3)
    g = _rnea(prog, tree, joints, zero, zero, [_num(-x) for x in tree.gravity])
    taken: set[str] = set()
    blocks = _renumber([extract(prog, out, cse=cse, taken=taken) for out in (M, c, g)])
    return EquationsOfMotion(
        name=tree.name, dof_names=list(tree.dof_names),
        joint_types=["prismatic" if t == PRISMATIC else "revolute" for t in tree.jtype],
        gravity=np.array(tree.gravity, dtype=float), q=q, qd=qd,
        mass_matrix=blocks[0], coriolis=blocks[1], gravity_torque=blocks[2],
        derive_seconds=time.perf_counter() - t0,
    )
