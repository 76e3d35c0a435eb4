"""Forward and inverse kinematics of the harvester crane's end point (URDF link ``stick_tip``,
the centre of the Hooke joint), from the URDF geometry.

Chain (world z up): swing q1 about z at ``o_s`` (the carrier mount); boom pivot at ``b`` in the
turret frame, boom pitch q2 about (0,-1,0) (positive lifts); stick pivot ``l1`` along the boom, stick
pitch q3 about (0,-1,0) relative to the boom; the tip ``l2`` along the stick. With
r = b_x + l1 cos q2 + l2 cos(q2+q3) (horizontal reach) and h = b_z + l1 sin q2 + l2 sin(q2+q3):

    x = o_x + r cos q1,   y = o_y + r sin q1,   z = o_z + h

Inverse (analytic): q1 = atan2(y - o_y, x - o_x); in the boom plane with r' = r - b_x, h' = h - b_z,
cos q3 = (r'^2 + h'^2 - l1^2 - l2^2) / (2 l1 l2) with the stick folded below the boom (q3 < 0, the
harvester's working branch); q2 = atan2(h', r') - atan2(l2 sin q3, l1 + l2 cos q3).
"""

from __future__ import annotations

import math

import numpy as np

from sim_core.model.spec import RobotSpec


class HarvesterKinematics:
    def __init__(self, spec: RobotSpec):
        t = spec.tree
        i_sw, i_b, i_s = t.index("swing"), t.index("boom"), t.index("stick")
        for i, ax in ((i_sw, (0, 0, 1)), (i_b, (0, -1, 0)), (i_s, (0, -1, 0))):
            if not np.allclose(t.axis[i], ax) or not np.allclose(t.R_tree[i], np.eye(3)):
                raise ValueError(f"harvester kinematics: joint {t.dof_names[i]} is not the expected axis {ax}")
        self.origin = t.p_tree[i_sw].copy()           # m: swing axis origin in the world
        self.boom_pivot = t.p_tree[i_b].copy()        # m: in the turret frame
        self.l1 = float(np.linalg.norm(t.p_tree[i_s]))  # m: boom length (pivot to stick pivot)
        body, R, p = t.link_frames["stick_tip"]
        if body != i_s or abs(p[1]) > 1e-12 or abs(p[2]) > 1e-12 or abs(t.p_tree[i_s][1]) + abs(t.p_tree[i_s][2]) > 1e-12:
            raise ValueError("harvester kinematics: stick_tip must lie on the stick's x axis")
        self.l2 = float(p[0])                          # m: stick length (pivot to Hooke centre)
        self.dofs = ("swing", "boom", "stick")
        self.lower = np.array([t.lower[i] for i in (i_sw, i_b, i_s)])
        self.upper = np.array([t.upper[i] for i in (i_sw, i_b, i_s)])

    def forward(self, q) -> np.ndarray:
        """End point (m, world) for joint angles q = (swing, boom, stick) (rad)."""
        q1, q2, q3 = q
        r = self.boom_pivot[0] + self.l1 * math.cos(q2) + self.l2 * math.cos(q2 + q3)
        h = self.boom_pivot[2] + self.l1 * math.sin(q2) + self.l2 * math.sin(q2 + q3)
        return np.array([self.origin[0] + r * math.cos(q1), self.origin[1] + r * math.sin(q1), self.origin[2] + h])

    def jacobian(self, q) -> np.ndarray:
        """d(end point)/dq (m/rad), 3x3."""
        q1, q2, q3 = q
        r = self.boom_pivot[0] + self.l1 * math.cos(q2) + self.l2 * math.cos(q2 + q3)
        dr2 = -self.l1 * math.sin(q2) - self.l2 * math.sin(q2 + q3)
        dr3 = -self.l2 * math.sin(q2 + q3)
        dh2 = self.l1 * math.cos(q2) + self.l2 * math.cos(q2 + q3)
        dh3 = self.l2 * math.cos(q2 + q3)
        c, s = math.cos(q1), math.sin(q1)
        return np.array([[-r * s, dr2 * c, dr3 * c],
                         [r * c, dr2 * s, dr3 * s],
                         [0.0, dh2, dh3]])

    def inverse(self, p) -> np.ndarray:
        """Joint angles (rad) placing the end point at ``p`` (m, world); ValueError if out of reach."""
        d = np.asarray(p, dtype=float) - self.origin
        q1 = math.atan2(d[1], d[0])
        rr = math.hypot(d[0], d[1]) - self.boom_pivot[0]
        hh = d[2] - self.boom_pivot[2]
        c3 = (rr * rr + hh * hh - self.l1 ** 2 - self.l2 ** 2) / (2.0 * self.l1 * self.l2)
        if not -1.0 <= c3 <= 1.0:
            raise ValueError(f"end point {list(np.round(p, 4))} m is out of the crane's reach")
        q3 = -math.acos(c3)
        q2 = math.atan2(hh, rr) - math.atan2(self.l2 * math.sin(q3), self.l1 + self.l2 * math.cos(q3))
        return np.array([q1, q2, q3])

    def joint_rates(self, q, v) -> np.ndarray:
        """Joint speeds (rad/s) for end-point velocity ``v`` (m/s) at ``q``: J(q)^-1 v."""
        return np.linalg.solve(self.jacobian(q), np.asarray(v, dtype=float))
