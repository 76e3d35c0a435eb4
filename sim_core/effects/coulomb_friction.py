import math

from numba import njit

from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


class CoulombFriction(Effect):
    """Coulomb (dry) friction of seals and bearings, as a joint torque.

    tau_f = -T_c tanh(q' / v_s). It loads the actuator, not the flow: chamber pressures rise by
    the friction torque, the joint stalls when the hydraulic torque margin is small, and it stops
    slightly earlier at reversals. Seal friction is usually small in lubricated cylinders
    (Papadopoulos et al. 2003, Sec. III-d) but not in vane actuators.
    """

    name = "coulomb_friction"
    citation = "C. Canudas de Wit et al., 'A new model for control of systems with friction', IEEE TAC 40(3), 1995; " + CITE_CATALOG + " (§3.8)"
    PARAMETERS = (
        Parameter("torque", "N m", "Coulomb friction torque at the joint", 20.0, 0.0, 2e5),
        Parameter("smoothing_velocity", "rad/s", "velocity scale of the tanh regularisation", 0.01, 1e-4, 1.0),
    )

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_E_COULOMB] = 1.0
        lw.AP[a, L.AP_COUL_TORQUE] = params["torque"]
        lw.AP[a, L.AP_COUL_VEL] = params["smoothing_velocity"]


@njit(cache=True, inline="always")
def friction_torque(qd, torque, vs):
    """(tau_f, d tau_f / d qd) for joint velocity ``qd``."""
    t = math.tanh(qd / vs)
    return -torque * t, -torque * (1.0 - t * t) / vs
