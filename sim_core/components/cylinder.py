"""Double-acting single-rod (asymmetric) cylinder: on a revolute joint through its mounts, or acting
directly on a prismatic joint."""

import functools
import math

import numpy as np
from numba import njit

from ..kernel.layout import AP, XS, col
from .base import Component, Parameter, ParameterError
from .chambers import AREA_A, AREA_B, P_A, P_B, VDEAD_A, VDEAD_B, VISC, lower_relief

LK_C0, LK_D1, LK_D2, LK_LMIN, STROKE, LK_DIRECT, LK_OFFSET = AP.declare(
    "cylinder",
    col("LK_C0", "m^2", "linkage: L^2 = C0 - 2 (D1 cos q + D2 sin q)"),
    col("LK_D1", "m^2", "linkage D1"),
    col("LK_D2", "m^2", "linkage D2"),
    col("LK_LMIN", "m", "pin-to-pin length at full retraction"),
    col("STROKE", "m", "cylinder stroke"),
    col("LK_DIRECT", "-", "1.0: direct-acting (piston position x = q + LK_OFFSET, arm 1); 0.0: through the mounts"),
    col("LK_OFFSET", "m", "direct-acting: piston position at joint position 0"),
)
CYL_L, CYL_ARM = XS.declare(
    "cylinder",
    col("CYL_L", "m", "pin-to-pin length L at the actuator's current position (computed once per substep)"),
    col("CYL_ARM", "m/rad or m/m", "moment arm dL/dq there (1 for a direct-acting cylinder)"),
)

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

    ``linkage = "direct"``: the cylinder acts along a prismatic joint (a ram lifting a carriage, a
    test-bench cylinder pushing a load): x = q + offset (m), dL/dq = 1, the force acts on the joint
    as it is (N); no mounts. ``offset`` defaults to -q_lower and ``stroke`` to q_upper - q_lower
    (the URDF limits are the stroke ends); x must stay in [0, stroke] over the joint range.

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
        Parameter("linkage", "-", "'mounts': through base and rod pins on a revolute joint; 'direct': along a prismatic joint",
                  "mounts", kind="choice", choices=("mounts", "direct")),
        Parameter("base_mount", "m", "cylinder base pin in the parent joint frame (linkage 'mounts')", (), kind="vec3"),
        Parameter("rod_mount", "m", "rod-eye pin in the child link frame (linkage 'mounts')", (), kind="vec3"),
        Parameter("offset", "m", "linkage 'direct': piston position at joint position 0; 'auto' = -q_lower", "auto",
                  -10.0, 10.0),
        Parameter("stroke", "m", "linkage 'direct': piston stroke; 'auto' = q_upper - q_lower", "auto", 1e-3, 20.0),
        Parameter("dead_volume_a", "m^3", "cap-side volume at full retraction (end cap, ports, manifold)", None, 0.0, 1.0),
        Parameter("dead_volume_b", "m^3", "rod-side volume at full extension", None, 0.0, 1.0),
        Parameter("viscous_friction", "N s/m", "viscous seal friction on the rod", 0.0, 0.0, 1e7),
        Parameter("port_relief_pressure", "Pa", "cross-port relief cracking pressure; 0 = none", 0.0, 0.0, 1e8),
    )

    def __init__(self, values=None, where=""):
        super().__init__(values, where)
        if self.values["rod_diameter"] >= self.values["bore"]:
            raise ParameterError(f"{self.where}.rod_diameter: must be smaller than the bore")
        if self.direct:
            extra = [k for k in ("base_mount", "rod_mount") if self.values[k] != ()]
            if extra:
                raise ParameterError(f"{self.where}: {', '.join(extra)} given but linkage = 'direct' has no mounts")
        else:
            for k in ("base_mount", "rod_mount"):
                if self.values[k] == ():
                    raise ParameterError(f"{self.where}.{k}: required parameter missing (m): "
                                         f"{self.PARAMETER_DOC[k]} (or linkage = 'direct' on a prismatic joint)")
            extra = [k for k in ("offset", "stroke") if self.values[k] != "auto"]
            if extra:
                raise ParameterError(f"{self.where}: {', '.join(extra)} only apply to linkage = 'direct'")

    PARAMETER_DOC = {"base_mount": "cylinder base pin in the parent joint frame",
                     "rod_mount": "rod-eye pin in the child link frame"}

    @property
    def direct(self) -> bool:
        return self.values["linkage"] == "direct"

    def direct_geometry(self, lower: float, upper: float) -> tuple[float, float]:
        """(offset, stroke) in m of a direct-acting cylinder on a joint with limits [lower, upper] (m)."""
        if not (math.isfinite(lower) and math.isfinite(upper)):
            raise ParameterError(f"{self.where}: a cylinder-driven joint needs finite limits in the URDF")
        off = -lower if self.values["offset"] == "auto" else float(self.values["offset"])
        stroke = upper - lower if self.values["stroke"] == "auto" else float(self.values["stroke"])
        if lower + off < -1e-9 or upper + off > stroke + 1e-9:
            raise ParameterError(
                f"{self.where}: piston position x = q + offset runs over [{lower + off:.4g}, {upper + off:.4g}] m "
                f"on the joint range [{lower:.4g}, {upper:.4g}] m; it must stay within [0, stroke = {stroke:.4g}] m"
            )
        return off, stroke

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
        c0, d1, d2, l_min, stroke, min_l2, min_arm = _linkage(
            tuple(float(x) for x in axis), float(lower), float(upper),
            tuple(float(x) for x in self.values["base_mount"]), tuple(float(x) for x in self.values["rod_mount"]))
        if min_l2 <= 0.0:
            raise ParameterError(f"{self.where}: mounts coincide somewhere in the joint range")
        if min_arm <= 1e-4:
            raise ParameterError(
                f"{self.where}: positive joint motion must extend the cylinder over the whole range "
                f"[{lower}, {upper}] rad (moment arm falls to {min_arm:.4g} m); move the mounts"
            )
        return c0, d1, d2, l_min, stroke

    def check_geometry(self, tree, i: int) -> None:
        """Raise :class:`ParameterError` unless the cylinder fits joint ``i`` of ``tree`` over its range."""
        if self.direct:
            if tree.jtype is None or tree.jtype[i] != 1:
                raise ParameterError(f"{self.where}: linkage = 'direct' needs a prismatic joint; "
                                     f"{tree.dof_names[i]!r} is revolute in the URDF "
                                     f"(give base_mount and rod_mount instead)")
            self.direct_geometry(tree.lower[i], tree.upper[i])
        else:
            if tree.jtype is not None and tree.jtype[i] == 1:
                raise ParameterError(f"{self.where}: the joint is prismatic; a cylinder on it acts directly: "
                                     f"set linkage = 'direct' (and drop the mounts)")
            self.linkage(tree.axis[i], tree.lower[i], tree.upper[i])

    def arms(self, tree, i: int, qs) -> np.ndarray:
        """dL/dq at joint positions ``qs`` of joint ``i`` (m/rad through mounts; 1 when direct-acting)."""
        qs = np.asarray(qs, dtype=float)
        if self.direct:
            return np.ones_like(qs)
        c0, d1, d2, _, _ = self.linkage(tree.axis[i], tree.lower[i], tree.upper[i])
        return (d1 * np.sin(qs) - d2 * np.cos(qs)) / np.sqrt(c0 - 2 * (d1 * np.cos(qs) + d2 * np.sin(qs)))

    KIND = "cylinder"
    KERNEL = {"prime": "cylinder_prime", "force": "cylinder_force", "geometry": "cylinder_geometry"}

    def lower(self, lw, a, spec, js):
        tree = spec.tree
        i = tree.index(js.dof)
        AP_ = lw.AP
        AP_[a, AREA_A] = self.area_a
        AP_[a, AREA_B] = self.area_b
        self.check_geometry(tree, i)
        if self.direct:
            off, stroke = self.direct_geometry(tree.lower[i], tree.upper[i])
            AP_[a, LK_DIRECT], AP_[a, LK_OFFSET] = 1.0, off
            AP_[a, LK_C0], AP_[a, LK_D1], AP_[a, LK_D2] = 0.0, 0.0, 0.0
            AP_[a, LK_LMIN], AP_[a, STROKE] = 0.0, stroke
        else:
            c0, d1, d2, lmin, stroke = self.linkage(tree.axis[i], tree.lower[i], tree.upper[i])
            AP_[a, LK_DIRECT], AP_[a, LK_OFFSET] = 0.0, 0.0
            AP_[a, LK_C0], AP_[a, LK_D1], AP_[a, LK_D2] = c0, d1, d2
            AP_[a, LK_LMIN], AP_[a, STROKE] = lmin, stroke
        AP_[a, VDEAD_A] = self["dead_volume_a"]
        AP_[a, VDEAD_B] = self["dead_volume_b"]
        AP_[a, VISC] = self["viscous_friction"]
        lower_relief(lw, a, self["port_relief_pressure"], js.components["valve"]["rated_flow"])

    @staticmethod
    def holding_pressures(AP_row, th, tau, pm):
        """Chamber pressures (Pa) around the mean ``pm`` that hold joint torque ``tau`` at ``th``,
        spread over both chambers in proportion to their areas (least-norm deviation from ``pm``)."""
        _, arm = piston_position(th, AP_row)
        A_a, A_b = AP_row[AREA_A], AP_row[AREA_B]
        lam = (tau / arm - pm * (A_a - A_b)) / (A_a ** 2 + A_b ** 2)
        return pm + lam * A_a, pm - lam * A_b

    @staticmethod
    def max_force(AP_row, lower, upper, p_supply):
        """Largest joint torque at full supply pressure over the joint range (N m)."""
        return p_supply * AP_row[AREA_A] * float(Cylinder.moment_arms(AP_row, np.linspace(lower, upper, 50)).max())

    @staticmethod
    def moment_arms(AP_row, qs):
        """dL/dq (m/rad, or 1 for a direct-acting cylinder) at joint positions ``qs`` from a lowered actuator row."""
        if AP_row[LK_DIRECT] != 0.0:
            return np.ones_like(np.asarray(qs, dtype=float))
        c0, d1, d2 = AP_row[LK_C0], AP_row[LK_D1], AP_row[LK_D2]
        return (d1 * np.sin(qs) - d2 * np.cos(qs)) / np.sqrt(c0 - 2 * (d1 * np.cos(qs) + d2 * np.sin(qs)))

    @staticmethod
    def chamber_volumes(AP_row, th):
        """(V_A, V_B) in m^3 at actuator angle ``th`` (stored-energy bookkeeping)."""
        L, _ = piston_position(th, AP_row)
        x = L - AP_row[LK_LMIN]
        return AP_row[VDEAD_A] + AP_row[AREA_A] * x, AP_row[VDEAD_B] + AP_row[AREA_B] * (AP_row[STROKE] - x)


@njit(inline="always")
def cylinder_length(q, c0, d1, d2):
    """Pin-to-pin length L (m) and moment arm dL/dq (m/rad) at joint angle ``q``."""
    c = math.cos(q)
    s = math.sin(q)
    L2 = c0 - 2.0 * (d1 * c + d2 * s)
    if L2 < 1e-12:
        L2 = 1e-12
    L = math.sqrt(L2)
    return L, (d1 * s - d2 * c) / L


def piston_position(th, AP_row):
    """(L, dL/dq) of a lowered actuator row at actuator position ``th`` (Python side)."""
    if AP_row[LK_DIRECT] != 0.0:
        return th + AP_row[LK_OFFSET], 1.0
    return cylinder_length(th, AP_row[LK_C0], AP_row[LK_D1], AP_row[LK_D2])


@njit(inline="always")
def _length(a, th, AP):
    if AP[a, LK_DIRECT] != 0.0:
        return th + AP[a, LK_OFFSET], 1.0
    return cylinder_length(th, AP[a, LK_C0], AP[a, LK_D1], AP[a, LK_D2])


@njit(inline="always")
def cylinder_prime(a, th, AP, XS):
    """Cache L and dL/dq at the actuator position ``th``."""
    L, arm = _length(a, th, AP)
    XS[a, CYL_L] = L
    XS[a, CYL_ARM] = arm


@njit(inline="always")
def cylinder_force(a, AP, XS):
    """Joint torque of the chamber pressures (N m) and the seal friction referred to the joint
    (N m s/rad), at the cached angle."""
    arm = XS[a, CYL_ARM]
    tau_h = (XS[a, P_A] * AP[a, AREA_A] - XS[a, P_B] * AP[a, AREA_B]) * arm
    return tau_h, AP[a, VISC] * arm * arm


@njit(inline="always")
def cylinder_geometry(a, th, om, AP, XS):
    """Chamber volumes (m^3), displaced flows (m^3/s) and volume rates (m^3/s) at angle ``th`` and rate
    ``om``; caches L and the arm for the next substep's force."""
    L, arm = _length(a, th, AP)
    XS[a, CYL_L] = L
    XS[a, CYL_ARM] = arm
    x = L - AP[a, LK_LMIN]
    xd = arm * om
    va = AP[a, VDEAD_A] + AP[a, AREA_A] * x
    vb = AP[a, VDEAD_B] + AP[a, AREA_B] * (AP[a, STROKE] - x)
    qdisp_a = AP[a, AREA_A] * xd
    qdisp_b = -AP[a, AREA_B] * xd
    return va, vb, qdisp_a, qdisp_b, qdisp_a, qdisp_b    # volumes change with the displaced flows


@functools.lru_cache(maxsize=256)
def _linkage(axis: tuple, lower: float, upper: float, base_mount: tuple, rod_mount: tuple):
    """The mounting geometry over the joint range: (C0, D1, D2, L_min, stroke, min L^2, min arm).
    Cached: every lowering and every parameter change checks it, and it only depends on the mounts."""
    k = np.asarray(axis, dtype=float)
    rb = np.asarray(base_mount, dtype=float)
    rr = np.asarray(rod_mount, dtype=float)
    r_par = np.dot(rr, k) * k
    r_perp = rr - r_par
    c0 = float(rb @ rb + rr @ rr - 2.0 * rb @ r_par)
    d1 = float(rb @ r_perp)
    d2 = float(rb @ np.cross(k, r_perp))
    qs = np.linspace(lower, upper, 201)
    L2 = c0 - 2.0 * (d1 * np.cos(qs) + d2 * np.sin(qs))
    min_l2 = float(L2.min())
    if min_l2 <= 0.0:
        return c0, d1, d2, math.nan, math.nan, min_l2, math.nan
    arm = (d1 * np.sin(qs) - d2 * np.cos(qs)) / np.sqrt(L2)
    L = np.sqrt(L2)
    return c0, d1, d2, float(L[0]), float(L[-1] - L[0]), min_l2, float(arm.min())
