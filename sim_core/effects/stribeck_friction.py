import math

from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, col
from .base import Effect

STRIBECK_STATIC, STRIBECK_COULOMB, STRIBECK_VEL, STRIBECK_SMOOTH = AP.declare(
    "stribeck_friction",
    col("STRIBECK_STATIC", "N m or N", "breakaway (static) friction"),
    col("STRIBECK_COULOMB", "N m or N", "sliding (Coulomb) friction"),
    col("STRIBECK_VEL", "rad/s or m/s", "Stribeck velocity"),
    col("STRIBECK_SMOOTH", "rad/s or m/s", "tanh smoothing velocity around zero speed"),
)


class StribeckFriction(Effect):
    """Stribeck friction: breakaway friction that falls to the Coulomb level as the joint speeds up.

    tau_f = -tanh(q'/v_e) [T_c + (T_s - T_c) exp(-(q'/v_s)^2)]. Starting from rest the actuator
    must overcome T_s, then the friction drops towards T_c within a few v_s: the joint jumps into
    motion (stick-slip at low speed), and stops a little before a Coulomb-only model would.
    Seals of hydraulic cylinders show it strongly at low pressure (Canudas de Wit et al. 1995).
    It is a simulation effect only: the diagnosis does not fit it (``candidate`` is None), so a
    record made with it tests how diagnose behaves on physics its bank cannot name.
    """

    name = "stribeck_friction"
    citation = ("C. Canudas de Wit, H. Olsson, K. J. Astrom, P. Lischinsky, 'A new model for control of "
                "systems with friction', IEEE TAC 40(3), 1995; B. Armstrong-Helouvry, Control of Machines "
                "with Friction, 1991")
    PARAMETERS = (
        Parameter("static_torque", "N m or N", "breakaway friction at zero speed", 40.0, 0.0, 2e5),
        Parameter("coulomb_torque", "N m or N", "friction at speeds well above the Stribeck velocity", 20.0, 0.0, 2e5),
        Parameter("stribeck_velocity", "rad/s or m/s", "speed over which the friction falls from static to Coulomb", 0.02, 1e-4, 1.0),
        Parameter("smoothing_velocity", "rad/s or m/s", "velocity scale of the tanh regularisation at zero speed", 0.002, 1e-5, 0.1),
    )
    HOOKS = {"joint_friction": "stribeck_torque"}

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, STRIBECK_STATIC] = params["static_torque"]
        lw.AP[a, STRIBECK_COULOMB] = params["coulomb_torque"]
        lw.AP[a, STRIBECK_VEL] = params["stribeck_velocity"]
        lw.AP[a, STRIBECK_SMOOTH] = params["smoothing_velocity"]


@njit(inline="always")
def stribeck_torque(a, qd_dof, AP):
    """(tau_f, its slope d tau_f / d qd) for joint velocity ``qd_dof``. Where the friction falls with
    speed the slope is positive (negative damping): the kernel treats only the dissipative part
    implicitly, so that slope is returned clipped at 0 (the falling part acts explicitly)."""
    tc = AP[a, STRIBECK_COULOMB]
    ds = AP[a, STRIBECK_STATIC] - tc
    vs = AP[a, STRIBECK_VEL]
    ve = AP[a, STRIBECK_SMOOTH]
    x = qd_dof / vs
    e = math.exp(-x * x)
    level = tc + ds * e
    t = math.tanh(qd_dof / ve)
    dlevel = -2.0 * x / vs * ds * e
    slope = -(1.0 - t * t) / ve * level - t * dlevel
    return -t * level, slope if slope < 0.0 else 0.0
