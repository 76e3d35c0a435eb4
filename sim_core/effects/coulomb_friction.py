import math

from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, col
from .base import CITE_CATALOG, Effect, clip_grid

COUL_TORQUE, COUL_VEL = AP.declare(
    "coulomb_friction",
    col("COUL_TORQUE", "N m or N", "Coulomb friction at the joint"),
    col("COUL_VEL", "rad/s or m/s", "tanh smoothing velocity"),
)


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
        Parameter("torque", "N m or N", "Coulomb friction torque at the joint (a force in N on a prismatic joint)", 20.0, 0.0, 2e5),
        Parameter("smoothing_velocity", "rad/s or m/s", "velocity scale of the tanh regularisation", 0.01, 1e-4, 1.0),
    )
    HOOKS = {"joint_friction": "friction_at_joint"}
    CONFUSIONS = {"payload": "chamber pressures while raising and lowering"}

    @classmethod
    def lower_neutral(cls, lw, a):
        lw.AP[a, COUL_VEL] = 0.01

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, COUL_TORQUE] = params["torque"]
        lw.AP[a, COUL_VEL] = params["smoothing_velocity"]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        T = scales["torque"]
        lo, hi = 1e-4 * T, 0.6 * T
        grid = [T * f for f in (0.003, 0.01, 0.025, 0.05, 0.1, 0.2, 0.35)]
        null = current["torque"] if current else 0.0
        return {"free": [("torque", lo, hi, True, null, "N m")],
                "fixed": {"smoothing_velocity": (current or {}).get("smoothing_velocity", 0.01)},
                "grid": [[v] for v in clip_grid(grid, lo, hi)]}


@njit(inline="always")
def friction_torque(qd, torque, vs):
    """(tau_f, d tau_f / d qd) for joint velocity ``qd``."""
    t = math.tanh(qd / vs)
    return -torque * t, -torque * (1.0 - t * t) / vs


@njit(inline="always")
def friction_at_joint(a, qd_dof, AP):
    return friction_torque(qd_dof, AP[a, COUL_TORQUE], AP[a, COUL_VEL])
