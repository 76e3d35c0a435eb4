import math

from numba import njit

from ..components.base import Parameter
from ..components.labview_adaptation import CITATION_MARS_ND
from ..kernel.layout import AP, XG_E_ACT, XG_E_MECH, XS, col
from .base import CITE_CATALOG, Effect, clip_grid

COMP_K, COMP_C, COMP_JA = AP.declare(
    "joint_compliance",
    col("COMP_K", "N m/rad", "stiffness between actuator and link"),
    col("COMP_C", "N m s/rad", "damping of the compliance"),
    col("COMP_JA", "kg m^2", "actuator-side inertia"),
)
TH_A, OM_A = XS.declare(
    "joint_compliance",
    col("TH_A", "rad", "actuator-side angle (the joint's when the effect is off)", ode=True, atol=1e-10),
    col("OM_A", "rad/s", "actuator-side rate", ode=True, atol=1e-10),
)


class JointCompliance(Effect):
    """Structural compliance between actuator and link (mounts, flexible links): a two-mass joint.

    J_a th_a'' = tau_hyd - k (th_a - q) - c (th_a' - q'); the link receives k (th_a - q) + c (th_a' - q').
    k = J (2 pi f)^2 and c = 2 zeta sqrt(k J) with J the link's own inertia about the joint at the
    initial pose, J_a = r J. The link rings at about f after every start and stop (a lightly damped
    resonance in the angle and the pressures); the MARS-ND model was tuned on joint stiffness.
    """

    name = "joint_compliance"
    citation = CITATION_MARS_ND + " (Sec. IV, joint stiffness tuning); " + CITE_CATALOG + " (§3.14)"
    PARAMETERS = (
        Parameter("frequency", "Hz", "natural frequency of the link on the compliance, actuator locked", 5.0, 0.2, 100.0),
        Parameter("damping_ratio", "-", "damping ratio of that mode", 0.1, 0.005, 2.0),
        Parameter("inertia_ratio", "-", "actuator-side inertia as a fraction of the link inertia", 0.2, 0.02, 2.0),
    )
    HOOKS = {
        "actuator_motion": "actuator_side_motion", "actuator_motion_off": "follow_joint",
        "coupling": "implicit_two_mass", "after_mechanics": "book_two_mass", "reference_coupling": "two_mass_derivative",
    }
    CONFUSIONS = {
        "line_dynamics": "pressures at the valve port and at the cylinder port, or a second record with another payload (a mechanical mode moves with the load)",
        "bulk_modulus": "chamber pressures (air softens the pressure build-up, a mechanical compliance does not)",
    }

    @classmethod
    def lower_neutral(cls, lw, a):
        lw.AP[a, COMP_JA] = 1.0

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        from ..kernel.layout import AP_DOF

        J = lw.joint_inertia[int(lw.AP[a, AP_DOF])]
        w = 2.0 * math.pi * params["frequency"]
        k = J * w * w
        lw.AP[a, COMP_K] = k
        lw.AP[a, COMP_C] = 2.0 * params["damping_ratio"] * math.sqrt(k * J)
        lw.AP[a, COMP_JA] = params["inertia_ratio"] * J

    @classmethod
    def reset(cls, ctx, a, q_dof, tau, on):
        # the spring starts pre-loaded with the torque that holds the link
        ctx.XS[a, TH_A] = q_dof + tau / ctx.AP[a, COMP_K] if on else q_dof
        ctx.XS[a, OM_A] = 0.0

    @classmethod
    def stored_energy(cls, ctx, a, out):
        from ..kernel.layout import AP_DOF

        q = ctx.XQ[0, int(ctx.AP[a, AP_DOF])]
        out["springs"] += 0.5 * ctx.AP[a, COMP_K] * (ctx.XS[a, TH_A] - q) ** 2
        out["kinetic"] += 0.5 * ctx.AP[a, COMP_JA] * ctx.XS[a, OM_A] ** 2
        return False

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        freqs = [0.8, 1.6, 3.0, 5.0, 8.0, 14.0, 25.0]
        if "frequency" in guess:
            freqs.append(guess["frequency"])
        cur = current or {}
        return {"free": [("frequency", 0.3, 60.0, True, cur.get("frequency", math.inf), "Hz"),
                         ("damping_ratio", 0.01, 1.5, True, cur.get("damping_ratio", math.nan), "")],
                "fixed": {"inertia_ratio": cur.get("inertia_ratio", 0.2), "damping_ratio": cur.get("damping_ratio", 0.1)},
                "grid": [[f, 0.1] for f in clip_grid(freqs, 0.3, 60.0)]}

    @classmethod
    def signature_guess(cls, sig, context):
        f = sig.get("residual_peak_hz")
        return {"frequency": float(f)} if f else None


@njit(inline="always")
def actuator_side_motion(a, dof, q, qd, AP, XS):
    return XS[a, TH_A], XS[a, OM_A]


@njit(inline="always")
def follow_joint(a, dof, q, qd, AP, XS):
    XS[a, TH_A] = q[dof]
    XS[a, OM_A] = qd[dof]


@njit(inline="always")
def implicit_two_mass(a, dof, h, tau_h, visc, q, qd, AP, XS, XG, energy):
    """Actuator side J_a th'' = tau_h - visc om - k (th - q) - c (om - qd), implicit in om; the link
    gets the spring-damper torque (returned with its damping slope and as the actuator's work)."""
    k = AP[a, COMP_K]
    c = AP[a, COMP_C]
    ja = AP[a, COMP_JA]
    th = XS[a, TH_A]
    om = XS[a, OM_A]
    om_new = (om + h * (tau_h - k * (th - q[dof]) + c * qd[dof]) / ja) / (1.0 + h * (visc + c) / ja)
    th_new = th + h * om_new
    if energy:   # the hydraulic work goes into the actuator side; the seal friction is lost there
        XG[XG_E_ACT] += h * tau_h * 0.5 * (om + om_new)
        XG[XG_E_MECH] += h * visc * om_new * 0.5 * (om + om_new)
    XS[a, OM_A] = om_new
    XS[a, TH_A] = th_new
    link = k * (th_new - q[dof]) + c * (om_new - qd[dof])
    return link, c, 0.0     # the link force is internal to the two-mass joint: no actuator work on the link


@njit(inline="always")
def book_two_mass(a, dof, h, q, qd, qd_old, AP, XS, XG):
    """Energy ledger: the compliance's damper acts between the two masses, c (om - qd)^2, not
    against the ground as the generic joint ledger booked it (c qd_new vavg)."""
    c = AP[a, COMP_C]
    rel = XS[a, OM_A] - qd[dof]
    XG[XG_E_MECH] += h * c * (rel * rel - qd[dof] * 0.5 * (qd[dof] + qd_old[dof]))


@njit(inline="always")
def two_mass_derivative(a, dof, tau_h, visc, q, qd, AP, XS, dXS):
    """Reference solver: th_a' = om_a, J_a om_a' = tau_h - visc om_a - spring; returns the spring torque."""
    th = XS[a, TH_A]
    om = XS[a, OM_A]
    spring = AP[a, COMP_K] * (th - q[dof]) + AP[a, COMP_C] * (om - qd[dof])
    dXS[a, TH_A] = om
    dXS[a, OM_A] = (tau_h - visc * om - spring) / AP[a, COMP_JA]
    return spring
