"""Double-acting single-rod (asymmetric) cylinder acting on a revolute joint through its mounts."""

import math

import numpy as np
from numba import njit

from .base import Component, Parameter, ParameterError

CITATION_CYLINDER = (
    "H. E. Merritt, Hydraulic Control Systems, Wiley, 1967, ch. 5; E. Papadopoulos et al., "
    "IEEE/ASME T-Mech 8(2), 2003, Sec. III-d (single-ended cylinders as two gyrators)"
)


class Cylinder(Component):
    """Asymmetric cylinder between a mount on the parent link and a mount on the child link.

    Geometry: with the joint axis k, the base mount r_b (parent side, joint frame) and the rod
    mount r_r (child frame), the pin-to-pin length is

        L(q)^2 = C0 - 2 (D1 cos q + D2 sin q),   C0 = |r_b|^2 + |r_r|^2 - 2 r_b.r_par,
        D1 = r_b.r_perp,  D2 = r_b.(k x r_perp)   (r_par, r_perp: parts of r_r along/across k)
        dL/dq = (D1 sin q - D2 cos q) / L          (the moment arm)

    Positive joint motion extends the cylinder (checked over the joint range); the stroke ends are
    the joint limits, so x = L(q) - L(q_lower) in [0, stroke].

    Hydraulics (chamber A = cap side, B = rod side):

        V_A = V_0A + A_A x,      V_B = V_0B + A_B (stroke - x)
        C_A dp_A/dt = Q_A - A_A dx/dt - Q_leak,   C_B dp_B/dt = Q_B + A_B dx/dt + Q_leak
        F = p_A A_A - p_B A_B - b_v dx/dt,        tau_joint = F dL/dq

    with C = V/beta (plus the hose compliance when the hose is lumped in).
    """

    section = "cylinder"
    citation = CITATION_CYLINDER
    PARAMETERS = (
        Parameter("bore", "m", "piston diameter", None, 5e-3, 1.0),
        Parameter("rod_diameter", "m", "rod diameter", None, 1e-3, 1.0),
        Parameter("base_mount", "m", "cylinder base pin in the parent joint frame", None, kind="vec3"),
        Parameter("rod_mount", "m", "rod-eye pin in the child link frame", None, kind="vec3"),
        Parameter("dead_volume_a", "m^3", "cap-side volume at full retraction (end cap, ports, manifold)", None, 0.0, 1.0),
        Parameter("dead_volume_b", "m^3", "rod-side volume at full extension", None, 0.0, 1.0),
        Parameter("viscous_friction", "N s/m", "viscous seal friction on the rod", 0.0, 0.0, 1e7),
        Parameter("port_relief_pressure", "Pa", "cross-port relief cracking pressure; 0 = none", 0.0, 0.0, 1e8),
    )

    def __init__(self, values=None, where=""):
        super().__init__(values, where)
        if self.values["rod_diameter"] >= self.values["bore"]:
            raise ParameterError(f"{self.where}.rod_diameter: must be smaller than the bore")

    @property
    def area_a(self) -> float:
        return math.pi * self.values["bore"] ** 2 / 4.0

    @property
    def area_b(self) -> float:
        return self.area_a - math.pi * self.values["rod_diameter"] ** 2 / 4.0

    def linkage(self, axis, lower: float, upper: float) -> tuple[float, float, float, float, float]:
        """(C0, D1, D2, L_min, stroke) for a joint with unit ``axis`` and limits [lower, upper]."""
        if not (math.isfinite(lower) and math.isfinite(upper)):
            raise ParameterError(f"{self.where}: a cylinder-driven joint needs finite limits in the URDF")
        k = np.asarray(axis, dtype=float)
        rb = np.asarray(self.values["base_mount"])
        rr = np.asarray(self.values["rod_mount"])
        r_par = np.dot(rr, k) * k
        r_perp = rr - r_par
        c0 = float(rb @ rb + rr @ rr - 2.0 * rb @ r_par)
        d1 = float(rb @ r_perp)
        d2 = float(rb @ np.cross(k, r_perp))
        qs = np.linspace(lower, upper, 201)
        L2 = c0 - 2.0 * (d1 * np.cos(qs) + d2 * np.sin(qs))
        if np.any(L2 <= 0.0):
            raise ParameterError(f"{self.where}: mounts coincide somewhere in the joint range")
        arm = (d1 * np.sin(qs) - d2 * np.cos(qs)) / np.sqrt(L2)
        if np.any(arm <= 1e-4):
            raise ParameterError(
                f"{self.where}: positive joint motion must extend the cylinder over the whole range "
                f"[{lower}, {upper}] rad (moment arm falls to {arm.min():.4g} m); move the mounts"
            )
        L = np.sqrt(L2)
        return c0, d1, d2, float(L[0]), float(L[-1] - L[0])


@njit(cache=True, inline="always")
def cylinder_length(q, c0, d1, d2):
    """Pin-to-pin length L (m) and moment arm dL/dq (m/rad) at joint angle ``q``."""
    c = math.cos(q)
    s = math.sin(q)
    L2 = c0 - 2.0 * (d1 * c + d2 * s)
    if L2 < 1e-12:
        L2 = 1e-12
    L = math.sqrt(L2)
    return L, (d1 * s - d2 * c) / L
