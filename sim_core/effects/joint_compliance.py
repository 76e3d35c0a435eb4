import math

from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect
from ..components.labview_adaptation import CITATION_MARS_ND


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

    @classmethod
    def lower(cls, params, lw, a):
        dof = int(lw.AP[a, L.AP_DOF])
        J = lw.joint_inertia[dof]
        w = 2.0 * math.pi * params["frequency"]
        k = J * w * w
        lw.AP[a, L.AP_E_COMPLIANCE] = 1.0
        lw.AP[a, L.AP_COMP_K] = k
        lw.AP[a, L.AP_COMP_C] = 2.0 * params["damping_ratio"] * math.sqrt(k * J)
        lw.AP[a, L.AP_COMP_JA] = params["inertia_ratio"] * J
