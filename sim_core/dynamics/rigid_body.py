"""Rigid-body dynamics of a tree of revolute and prismatic joints, compiled with numba,
allocation-free.

Everything is expressed in the world (root) frame, which keeps the recursions short:

* kinematics: revolute ``R_i = R_p R_tree,i Rot(a_i, q_i)``, ``o_i = o_p + R_p p_tree,i``;
  prismatic ``R_i = R_p R_tree,i``, ``o_i = o_p + R_p p_tree,i + a_i q_i`` (``q_i`` in m).
* RNEA (recursive Newton-Euler, Luh/Walker/Paul 1980) with the gravity trick (root acceleration
  ``-g``) gives ``tau = M(q) qdd + c(q, qd) + g(q)`` (N m for a revolute joint, N for a prismatic
  one).
* CRBA (composite rigid body, Walker & Orin 1982; Featherstone, *Rigid Body Dynamics Algorithms*,
  2008, ch. 6) in world coordinates: with motion subspace ``S_i = [a_i; o_i x a_i]`` (revolute) or
  ``S_i = [0; a_i]`` (prismatic) and the composite spatial inertia ``I^c_j`` of the subtree of
  ``j`` about the world origin, ``M_ij = S_i . (I^c_j S_j)`` for ``i`` an ancestor of ``j``.
* Tree-sparse ``M = L^T L`` factorisation (Featherstone's LTL, ch. 6.5): fill-in never leaves the
  ancestor pattern, so the two HydroLek arms of MARS-ND cost twice one arm, not eight times.

Forward dynamics ``qdd = M^-1 (tau - c - g)`` is what Pinocchio's ABA computes; the tests check the
two against each other to 1e-9.

The joint types come as a trailing optional argument ``jtype`` (int64 [n], ``REVOLUTE`` = 0,
``PRISMATIC`` = 1, as in :class:`sim_core.model.urdf.KinematicTree`). Omitted, or naming no
prismatic joint, the all-revolute code runs: each function holds it as a second copy with the
prismatic branches compiled out, so revolute trees pay one scan of ``jtype`` and give the same bits
with and without it. kinematics, crba and rnea are inlined into compiled callers (numba
``inline="always"``): no call boundary in the kernel's hot path.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..model.urdf import PRISMATIC
from .compiled_arg import compiled_arg

_NJ = dict(cache=True, nogil=True, fastmath=False)


@njit(inline="always", **_NJ)
def cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(inline="always", **_NJ)
def has_prismatic(jtype):
    """Whether a joint-type array (or None: all revolute) holds a prismatic joint."""
    if jtype is None:
        return False
    for i in range(jtype.shape[0]):
        if jtype[i] == PRISMATIC:
            return True
    return False


@njit(inline="always", **_NJ)
def kinematics(parent, R_tree, p_tree, axis, com, inertia, q, Rw, ow, aw, cw, Iw, tmp33, jtype=None):
    """World pose of every body: rotation ``Rw``, body origin ``ow`` (m; the joint origin, moved by
    ``q_i`` along the axis for a prismatic joint), axis ``aw``, COM ``cw`` (m), inertia about the
    COM ``Iw`` (kg m^2, world axes). ``jtype``: joint types (omitted: all revolute). ``tmp33`` is
    unused (the 3x3 products stay in registers); it is kept for the callers' signature."""
    if has_prismatic(jtype):
        _kinematics(parent, R_tree, p_tree, axis, com, inertia, q, Rw, ow, aw, cw, Iw, tmp33, jtype)
    else:  # all revolute: the prismatic branches are compiled away
        _kinematics(parent, R_tree, p_tree, axis, com, inertia, q, Rw, ow, aw, cw, Iw, tmp33, None)


# 3x3 matrices as row-major 9-tuples: kept in registers, summed in the order of a loop
# ``acc = 0.0; acc += x_k`` so that results are bit-identical to the loop form.
@njit(inline="always", **_NJ)
def _load33(A, i):
    return (A[i, 0, 0], A[i, 0, 1], A[i, 0, 2], A[i, 1, 0], A[i, 1, 1], A[i, 1, 2],
            A[i, 2, 0], A[i, 2, 1], A[i, 2, 2])


@njit(inline="always", **_NJ)
def _store33(A, i, a):
    A[i, 0, 0], A[i, 0, 1], A[i, 0, 2] = a[0], a[1], a[2]
    A[i, 1, 0], A[i, 1, 1], A[i, 1, 2] = a[3], a[4], a[5]
    A[i, 2, 0], A[i, 2, 1], A[i, 2, 2] = a[6], a[7], a[8]


@njit(inline="always", **_NJ)
def _mul33(a, b):
    """``a @ b``."""
    return (0.0 + a[0] * b[0] + a[1] * b[3] + a[2] * b[6],
            0.0 + a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
            0.0 + a[0] * b[2] + a[1] * b[5] + a[2] * b[8],
            0.0 + a[3] * b[0] + a[4] * b[3] + a[5] * b[6],
            0.0 + a[3] * b[1] + a[4] * b[4] + a[5] * b[7],
            0.0 + a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
            0.0 + a[6] * b[0] + a[7] * b[3] + a[8] * b[6],
            0.0 + a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
            0.0 + a[6] * b[2] + a[7] * b[5] + a[8] * b[8])


@njit(inline="always", **_NJ)
def _mul33t(a, b):
    """``a @ b.T``."""
    return (0.0 + a[0] * b[0] + a[1] * b[1] + a[2] * b[2],
            0.0 + a[0] * b[3] + a[1] * b[4] + a[2] * b[5],
            0.0 + a[0] * b[6] + a[1] * b[7] + a[2] * b[8],
            0.0 + a[3] * b[0] + a[4] * b[1] + a[5] * b[2],
            0.0 + a[3] * b[3] + a[4] * b[4] + a[5] * b[5],
            0.0 + a[3] * b[6] + a[4] * b[7] + a[5] * b[8],
            0.0 + a[6] * b[0] + a[7] * b[1] + a[8] * b[2],
            0.0 + a[6] * b[3] + a[7] * b[4] + a[8] * b[5],
            0.0 + a[6] * b[6] + a[7] * b[7] + a[8] * b[8])


@njit(inline="always", **_NJ)
def _rot(ax, q):
    """Rodrigues rotation matrix for unit axis ``ax`` and angle ``q`` (rad)."""
    c = np.cos(q)
    s = np.sin(q)
    t = 1.0 - c
    x, y, z = ax[0], ax[1], ax[2]
    return (t * x * x + c, t * x * y - s * z, t * x * z + s * y,
            t * x * y + s * z, t * y * y + c, t * y * z - s * x,
            t * x * z - s * y, t * y * z + s * x, t * z * z + c)


@njit(inline="always", **_NJ)
def _kinematics(parent, R_tree, p_tree, axis, com, inertia, q, Rw, ow, aw, cw, Iw, tmp33, jtype):
    n = parent.shape[0]
    for i in range(n):
        p = parent[i]
        prismatic = False
        if jtype is not None:
            prismatic = jtype[i] == PRISMATIC
        Rt = _load33(R_tree, i)
        if prismatic:
            A = Rt  # no rotation
        else:
            A = _mul33(Rt, _rot(axis[i], q[i]))
        pt0, pt1, pt2 = p_tree[i, 0], p_tree[i, 1], p_tree[i, 2]
        if p >= 0:
            P = _load33(Rw, p)
            B = _mul33(P, A)
            o0 = ow[p, 0] + P[0] * pt0 + P[1] * pt1 + P[2] * pt2
            o1 = ow[p, 1] + P[3] * pt0 + P[4] * pt1 + P[5] * pt2
            o2 = ow[p, 2] + P[6] * pt0 + P[7] * pt1 + P[8] * pt2
        else:
            B = A
            o0, o1, o2 = pt0, pt1, pt2
        x0, x1, x2 = axis[i, 0], axis[i, 1], axis[i, 2]
        a0 = 0.0 + B[0] * x0 + B[1] * x1 + B[2] * x2
        a1 = 0.0 + B[3] * x0 + B[4] * x1 + B[5] * x2
        a2 = 0.0 + B[6] * x0 + B[7] * x1 + B[8] * x2
        if prismatic:  # the body slides q_i (m) along the axis
            o0 += a0 * q[i]
            o1 += a1 * q[i]
            o2 += a2 * q[i]
        k0, k1, k2 = com[i, 0], com[i, 1], com[i, 2]
        _store33(Rw, i, B)
        ow[i, 0], ow[i, 1], ow[i, 2] = o0, o1, o2
        aw[i, 0], aw[i, 1], aw[i, 2] = a0, a1, a2
        cw[i, 0] = o0 + B[0] * k0 + B[1] * k1 + B[2] * k2
        cw[i, 1] = o1 + B[3] * k0 + B[4] * k1 + B[5] * k2
        cw[i, 2] = o2 + B[6] * k0 + B[7] * k1 + B[8] * k2
        _store33(Iw, i, _mul33t(_mul33(B, _load33(inertia, i)), B))  # R I R^T


@njit(inline="always", **_NJ)
def rnea(parent, mass, gravity, ow, aw, cw, Iw, qd, qdd, gscale, w, dw, ao, F, N, tau, jtype=None):
    """Inverse dynamics ``tau = M qdd + c(q, qd) + gscale * g(q)`` given world kinematics (``ao``:
    acceleration of each body origin, m/s^2; ``F``, ``N``: force (N) and moment about the body
    origin (N m) of each subtree). ``jtype``: joint types (omitted: all revolute)."""
    if has_prismatic(jtype):
        _rnea(parent, mass, gravity, ow, aw, cw, Iw, qd, qdd, gscale, w, dw, ao, F, N, tau, jtype)
    else:  # all revolute: the prismatic branches are compiled away
        _rnea(parent, mass, gravity, ow, aw, cw, Iw, qd, qdd, gscale, w, dw, ao, F, N, tau, None)


@njit(inline="always", **_NJ)
def _rnea(parent, mass, gravity, ow, aw, cw, Iw, qd, qdd, gscale, w, dw, ao, F, N, tau, jtype):
    n = parent.shape[0]
    for i in range(n):
        p = parent[i]
        prismatic = False
        if jtype is not None:
            prismatic = jtype[i] == PRISMATIC
        if p >= 0:
            wp0, wp1, wp2 = w[p, 0], w[p, 1], w[p, 2]
            dwp0, dwp1, dwp2 = dw[p, 0], dw[p, 1], dw[p, 2]
            d0, d1, d2 = ow[i, 0] - ow[p, 0], ow[i, 1] - ow[p, 1], ow[i, 2] - ow[p, 2]
            x0, x1, x2 = cross(dwp0, dwp1, dwp2, d0, d1, d2)
            y0, y1, y2 = cross(wp0, wp1, wp2, d0, d1, d2)
            z0, z1, z2 = cross(wp0, wp1, wp2, y0, y1, y2)
            ao[i, 0] = ao[p, 0] + x0 + z0
            ao[i, 1] = ao[p, 1] + x1 + z1
            ao[i, 2] = ao[p, 2] + x2 + z2
        else:
            wp0 = wp1 = wp2 = 0.0
            dwp0 = dwp1 = dwp2 = 0.0
            ao[i, 0] = -gscale * gravity[0]
            ao[i, 1] = -gscale * gravity[1]
            ao[i, 2] = -gscale * gravity[2]
        a0, a1, a2 = aw[i, 0], aw[i, 1], aw[i, 2]
        if prismatic:
            # the origin slides along the axis, which turns with the parent: a qdd + 2 w_p x a qd
            c0, c1, c2 = cross(wp0, wp1, wp2, a0 * qd[i], a1 * qd[i], a2 * qd[i])
            ao[i, 0] += a0 * qdd[i] + 2.0 * c0
            ao[i, 1] += a1 * qdd[i] + 2.0 * c1
            ao[i, 2] += a2 * qdd[i] + 2.0 * c2
            w[i, 0], w[i, 1], w[i, 2] = wp0, wp1, wp2
            dw[i, 0], dw[i, 1], dw[i, 2] = dwp0, dwp1, dwp2
        else:
            w[i, 0] = wp0 + a0 * qd[i]
            w[i, 1] = wp1 + a1 * qd[i]
            w[i, 2] = wp2 + a2 * qd[i]
            c0, c1, c2 = cross(wp0, wp1, wp2, a0 * qd[i], a1 * qd[i], a2 * qd[i])
            dw[i, 0] = dwp0 + a0 * qdd[i] + c0
            dw[i, 1] = dwp1 + a1 * qdd[i] + c1
            dw[i, 2] = dwp2 + a2 * qdd[i] + c2
        # COM acceleration
        r0, r1, r2 = cw[i, 0] - ow[i, 0], cw[i, 1] - ow[i, 1], cw[i, 2] - ow[i, 2]
        x0, x1, x2 = cross(dw[i, 0], dw[i, 1], dw[i, 2], r0, r1, r2)
        y0, y1, y2 = cross(w[i, 0], w[i, 1], w[i, 2], r0, r1, r2)
        z0, z1, z2 = cross(w[i, 0], w[i, 1], w[i, 2], y0, y1, y2)
        m = mass[i]
        f0 = m * (ao[i, 0] + x0 + z0)
        f1 = m * (ao[i, 1] + x1 + z1)
        f2 = m * (ao[i, 2] + x2 + z2)
        # moment about COM: I dw + w x (I w)
        Iw0 = Iw[i, 0, 0] * w[i, 0] + Iw[i, 0, 1] * w[i, 1] + Iw[i, 0, 2] * w[i, 2]
        Iw1 = Iw[i, 1, 0] * w[i, 0] + Iw[i, 1, 1] * w[i, 1] + Iw[i, 1, 2] * w[i, 2]
        Iw2 = Iw[i, 2, 0] * w[i, 0] + Iw[i, 2, 1] * w[i, 1] + Iw[i, 2, 2] * w[i, 2]
        g0, g1, g2 = cross(w[i, 0], w[i, 1], w[i, 2], Iw0, Iw1, Iw2)
        n0 = Iw[i, 0, 0] * dw[i, 0] + Iw[i, 0, 1] * dw[i, 1] + Iw[i, 0, 2] * dw[i, 2] + g0
        n1 = Iw[i, 1, 0] * dw[i, 0] + Iw[i, 1, 1] * dw[i, 1] + Iw[i, 1, 2] * dw[i, 2] + g1
        n2 = Iw[i, 2, 0] * dw[i, 0] + Iw[i, 2, 1] * dw[i, 1] + Iw[i, 2, 2] * dw[i, 2] + g2
        m0, m1, m2 = cross(r0, r1, r2, f0, f1, f2)
        F[i, 0], F[i, 1], F[i, 2] = f0, f1, f2
        N[i, 0], N[i, 1], N[i, 2] = n0 + m0, n1 + m1, n2 + m2
    for i in range(n - 1, -1, -1):
        prismatic = False
        if jtype is not None:
            prismatic = jtype[i] == PRISMATIC
        if prismatic:
            tau[i] = aw[i, 0] * F[i, 0] + aw[i, 1] * F[i, 1] + aw[i, 2] * F[i, 2]
        else:
            tau[i] = aw[i, 0] * N[i, 0] + aw[i, 1] * N[i, 1] + aw[i, 2] * N[i, 2]
        p = parent[i]
        if p >= 0:
            d0, d1, d2 = ow[i, 0] - ow[p, 0], ow[i, 1] - ow[p, 1], ow[i, 2] - ow[p, 2]
            m0, m1, m2 = cross(d0, d1, d2, F[i, 0], F[i, 1], F[i, 2])
            for k in range(3):
                F[p, k] += F[i, k]
            N[p, 0] += N[i, 0] + m0
            N[p, 1] += N[i, 1] + m1
            N[p, 2] += N[i, 2] + m2


@njit(inline="always", **_NJ)
def crba(parent, mass, ow, aw, cw, Iw, mc, hc, Ic, M, jtype=None):
    """Joint-space inertia matrix ``M`` (dense [n,n], only the tree pattern is non-zero; kg m^2,
    kg m or kg by joint types). ``jtype``: joint types (omitted: all revolute)."""
    if has_prismatic(jtype):
        _crba(parent, mass, ow, aw, cw, Iw, mc, hc, Ic, M, jtype)
    else:  # all revolute: the prismatic branches are compiled away
        _crba(parent, mass, ow, aw, cw, Iw, mc, hc, Ic, M, None)


@njit(inline="always", **_NJ)
def _crba(parent, mass, ow, aw, cw, Iw, mc, hc, Ic, M, jtype):
    n = parent.shape[0]
    # body spatial inertia about the world origin, then accumulate subtrees (children after parents)
    for i in range(n):
        m = mass[i]
        c0, c1, c2 = cw[i, 0], cw[i, 1], cw[i, 2]
        mc[i] = m
        hc[i, 0], hc[i, 1], hc[i, 2] = m * c0, m * c1, m * c2
        cc = c0 * c0 + c1 * c1 + c2 * c2
        for r in range(3):
            for c in range(3):
                Ic[i, r, c] = Iw[i, r, c] - m * cw[i, r] * cw[i, c]
            Ic[i, r, r] += m * cc
    for i in range(n - 1, -1, -1):
        p = parent[i]
        if p >= 0:
            mc[p] += mc[i]
            for r in range(3):
                hc[p, r] += hc[i, r]
                for c in range(3):
                    Ic[p, r, c] += Ic[i, r, c]
    for i in range(n):
        for j in range(n):
            M[i, j] = 0.0
    for j in range(n):
        a0, a1, a2 = aw[j, 0], aw[j, 1], aw[j, 2]
        h0, h1, h2 = hc[j, 0], hc[j, 1], hc[j, 2]
        m = mc[j]
        prismatic = False
        if jtype is not None:
            prismatic = jtype[j] == PRISMATIC
        if prismatic:
            # S_j = [0; a]: angular h x a, linear m a
            fa0, fa1, fa2 = cross(h0, h1, h2, a0, a1, a2)
            fl0, fl1, fl2 = m * a0, m * a1, m * a2
        else:
            o0, o1, o2 = ow[j, 0], ow[j, 1], ow[j, 2]
            v0, v1, v2 = cross(o0, o1, o2, a0, a1, a2)  # o x a
            # angular: Ic a + h x (o x a); linear: a x h + m (o x a)
            x0, x1, x2 = cross(h0, h1, h2, v0, v1, v2)
            fa0 = Ic[j, 0, 0] * a0 + Ic[j, 0, 1] * a1 + Ic[j, 0, 2] * a2 + x0
            fa1 = Ic[j, 1, 0] * a0 + Ic[j, 1, 1] * a1 + Ic[j, 1, 2] * a2 + x1
            fa2 = Ic[j, 2, 0] * a0 + Ic[j, 2, 1] * a1 + Ic[j, 2, 2] * a2 + x2
            y0, y1, y2 = cross(a0, a1, a2, h0, h1, h2)
            fl0, fl1, fl2 = y0 + m * v0, y1 + m * v1, y2 + m * v2
        i = j
        while i >= 0:
            b0, b1, b2 = aw[i, 0], aw[i, 1], aw[i, 2]
            row_prismatic = False
            if jtype is not None:
                row_prismatic = jtype[i] == PRISMATIC
            if row_prismatic:
                val = b0 * fl0 + b1 * fl1 + b2 * fl2
            else:
                s0, s1, s2 = cross(ow[i, 0], ow[i, 1], ow[i, 2], b0, b1, b2)
                val = b0 * fa0 + b1 * fa1 + b2 * fa2 + s0 * fl0 + s1 * fl1 + s2 * fl2
            M[i, j] = val
            M[j, i] = val
            i = parent[i]


@njit(**_NJ)
def ltl_factor(parent, H):
    """In-place tree-sparse factorisation ``H = L^T L`` (lower triangle of ``H`` becomes ``L``).
    Returns False if ``H`` is not positive definite."""
    n = parent.shape[0]
    for k in range(n - 1, -1, -1):
        if H[k, k] <= 0.0:
            return False
        H[k, k] = np.sqrt(H[k, k])
        i = parent[k]
        while i >= 0:
            H[k, i] = H[k, i] / H[k, k]
            i = parent[i]
        i = parent[k]
        while i >= 0:
            j = i
            while j >= 0:
                H[i, j] = H[i, j] - H[k, i] * H[k, j]
                j = parent[j]
            i = parent[i]
    return True


@njit(**_NJ)
def ltl_solve(parent, L, x):
    """Solve ``L^T L x = b`` in place (``x`` holds ``b`` on entry), ``L`` from :func:`ltl_factor`."""
    n = parent.shape[0]
    # L^T y = b  (backward over the tree: L^T is upper triangular)
    for i in range(n - 1, -1, -1):
        x[i] = x[i] / L[i, i]
        j = parent[i]
        while j >= 0:
            x[j] = x[j] - L[i, j] * x[i]
            j = parent[j]
    # L x = y
    for i in range(n):
        j = parent[i]
        while j >= 0:
            x[i] = x[i] - L[i, j] * x[j]
            j = parent[j]
        x[i] = x[i] / L[i, i]


@njit(**_NJ)
def potential_energy(mass, gravity, cw):
    """Gravitational potential energy (J) relative to the world origin."""
    e = 0.0
    for i in range(mass.shape[0]):
        e -= mass[i] * (gravity[0] * cw[i, 0] + gravity[1] * cw[i, 1] + gravity[2] * cw[i, 2])
    return e


class RigidBodyWorkspace:
    """Preallocated arrays for one tree; the kernel functions write into them, never allocate."""

    def __init__(self, n: int):
        self.Rw = np.zeros((n, 3, 3))
        self.ow = np.zeros((n, 3))
        self.aw = np.zeros((n, 3))
        self.cw = np.zeros((n, 3))
        self.Iw = np.zeros((n, 3, 3))
        self.tmp33 = np.zeros((3, 3))
        self.w = np.zeros((n, 3))
        self.dw = np.zeros((n, 3))
        self.ao = np.zeros((n, 3))
        self.F = np.zeros((n, 3))
        self.N = np.zeros((n, 3))
        self.mc = np.zeros(n)
        self.hc = np.zeros((n, 3))
        self.Ic = np.zeros((n, 3, 3))
        self.M = np.zeros((n, n))


class RigidBodyModel:
    """Convenience wrapper around the compiled functions for one :class:`KinematicTree` (tests,
    energy bookkeeping and the reference solver use it; the real-time kernel calls the compiled
    functions directly)."""

    def __init__(self, tree, mass=None, com=None, inertia=None):
        self.tree = tree
        self.parent = compiled_arg(tree.parent)
        self.R_tree = compiled_arg(tree.R_tree)
        self.p_tree = compiled_arg(tree.p_tree)
        self.axis = compiled_arg(tree.axis)
        self.jtype = compiled_arg(tree.jtype, dtype=np.int64)
        self.mass = compiled_arg(tree.mass if mass is None else mass, dtype=float)
        self.com = compiled_arg(tree.com if com is None else com, dtype=float)
        self.inertia = compiled_arg(tree.inertia if inertia is None else inertia, dtype=float)
        self.gravity = compiled_arg(tree.gravity, dtype=float)
        self.ws = RigidBodyWorkspace(tree.n)

    def _kin(self, q):
        ws = self.ws
        kinematics(self.parent, self.R_tree, self.p_tree, self.axis, self.com, self.inertia,
                   compiled_arg(q, dtype=float), ws.Rw, ws.ow, ws.aw, ws.cw, ws.Iw, ws.tmp33, self.jtype)

    def inverse_dynamics(self, q, qd, qdd, gravity: bool = True) -> np.ndarray:
        """Joint forces ``M qdd + c(q, qd) + g(q)`` (N m revolute, N prismatic)."""
        self._kin(q)
        ws = self.ws
        tau = np.zeros(self.tree.n)
        rnea(self.parent, self.mass, self.gravity, ws.ow, ws.aw, ws.cw, ws.Iw,
             compiled_arg(qd, dtype=float), compiled_arg(qdd, dtype=float),
             1.0 if gravity else 0.0, ws.w, ws.dw, ws.ao, ws.F, ws.N, tau, self.jtype)
        return tau

    def mass_matrix(self, q) -> np.ndarray:
        """Joint-space inertia ``M(q)``, a copy."""
        self._kin(q)
        ws = self.ws
        crba(self.parent, self.mass, ws.ow, ws.aw, ws.cw, ws.Iw, ws.mc, ws.hc, ws.Ic, ws.M, self.jtype)
        return ws.M.copy()

    def forward_dynamics(self, q, qd, tau) -> np.ndarray:
        """Joint accelerations (rad/s^2 revolute, m/s^2 prismatic) under joint forces ``tau``."""
        bias = self.inverse_dynamics(q, qd, np.zeros(self.tree.n))
        M = self.mass_matrix(q)
        x = np.asarray(tau, dtype=float) - bias
        if not ltl_factor(self.parent, M):
            raise FloatingPointError("mass matrix is not positive definite")
        ltl_solve(self.parent, M, x)
        return x

    def frames(self, q):
        """World rotation and origin (m) of every body frame at ``q`` (a prismatic body's frame is
        its joint frame moved by ``q_i`` along the axis)."""
        self._kin(q)
        return self.ws.Rw.copy(), self.ws.ow.copy()

    def kinetic_energy(self, q, qd) -> float:
        """``qd^T M(q) qd / 2`` (J)."""
        M = self.mass_matrix(q)
        qd = np.asarray(qd, dtype=float)
        return 0.5 * float(qd @ M @ qd)

    def potential_energy(self, q) -> float:
        """Gravitational potential energy (J) relative to the world origin."""
        self._kin(q)
        return float(potential_energy(self.mass, self.gravity, self.ws.cw))

    def link_pose(self, q, link: str):
        """World rotation and position of any URDF link frame at ``q``."""
        body, R, p = self.tree.link_frames[link]
        if body < 0:
            return R.copy(), p.copy()
        Rw, ow = self.frames(q)
        return Rw[body] @ R, ow[body] + Rw[body] @ p
