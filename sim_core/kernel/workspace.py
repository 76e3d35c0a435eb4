"""Named arrays the compiled kernel works in: the tree's structure and the per-call scratch space.

numba compiles attribute access on a namedtuple to a fixed field, so the kernel reads ``ws.M``
rather than element 14 of a tuple, and a field cannot be mixed up with its neighbour.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..dynamics.compiled_arg import compiled_arg
from ..model.urdf import PRISMATIC
from . import layout as L

TreeArrays = namedtuple("TreeArrays", "parent R_tree p_tree axis mass com inertia gravity jtype")

Workspace = namedtuple("Workspace", [
    # world kinematics of every body (rigid_body.kinematics)
    "Rw", "ow", "aw", "cw", "Iw", "tmp33",
    # recursions (RNEA, CRBA)
    "w", "dw", "ao", "F", "N", "mc", "hc", "Ic",
    # mass matrix, the factor of M + h dF/dqd and the diagonal it was factored with (Dfac) against
    # this substep's (Dnew), bias forces, zero accelerations
    "M", "Lf", "Dfac", "Dnew", "bias", "zero",
    # per joint: right-hand side, damping slope, friction and its slope, actuator work, stop stiffness,
    # velocities before the substep (energy ledger)
    "rhs", "Dlin", "Ffr", "Sfr", "Tact", "Kst", "qd0",
    # per actuator: metering spool position of the substep
    "spool_s",
    # command-chain discretisation scratch
    "Acc", "Bcc", "expw",
    # backup of the state for the roll-back on a non-finite state
    "bq", "bs", "bg",
])


def tree_arrays(tree, lowered) -> TreeArrays:
    """The kinematic tree with the lowered (payload-adjusted) masses and inertias, every array as
    the kernel's one compiled signature takes it (:func:`compiled_arg`)."""
    jtype = None     # all revolute: the prismatic branches are compiled out
    if tree.jtype is not None and np.any(np.asarray(tree.jtype) == PRISMATIC):
        jtype = compiled_arg(tree.jtype, dtype=np.int64)
    c = compiled_arg
    return TreeArrays(c(tree.parent), c(tree.R_tree), c(tree.p_tree), c(tree.axis), c(lowered.mass), c(lowered.com),
                      c(lowered.inertia), c(tree.gravity), jtype)


# the diagonal a factor was made with, marking it stale: no damping is within the tolerance of it, so
# the next substep factors afresh (also with a tolerance of 0 or below)
STALE = 1e300


def make_workspace(n: int, na: int) -> Workspace:
    """Scratch space for a tree of ``n`` joints driven by ``na`` actuators."""
    z = np.zeros
    return Workspace(
        Rw=z((n, 3, 3)), ow=z((n, 3)), aw=z((n, 3)), cw=z((n, 3)), Iw=z((n, 3, 3)), tmp33=z((3, 3)),
        w=z((n, 3)), dw=z((n, 3)), ao=z((n, 3)), F=z((n, 3)), N=z((n, 3)), mc=z(n), hc=z((n, 3)), Ic=z((n, 3, 3)),
        M=z((n, n)), Lf=z((n, n)), Dfac=np.full(n, STALE), Dnew=z(n), bias=z(n), zero=z(n),
        rhs=z(n), Dlin=z(n), Ffr=z(n), Sfr=z(n), Tact=z(n), Kst=z(n), qd0=z(n),
        spool_s=z(na),
        Acc=z((5, 5)), Bcc=z((5, 2)), expw=z((6, 7, 7)),
        bq=z((2, n)), bs=z((na, L.XS_N)), bg=z(L.XG_N),
    )
