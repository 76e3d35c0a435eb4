"""Joint mechanics besides the rigid bodies: limits with end stops, viscous joint damping, locking.

A joint past a limit meets a spring-damper that pushes but never pulls,

    tau_stop = -k (q - q_lim) - c q'   (only while it pushes back),

stiff enough that the actuator's full-pressure torque presses at most ``end_stop_penetration``
into it and never softer than ``end_stop_frequency`` on the link's own inertia; damping ratio
``end_stop_damping_ratio``. Both are implicit in the kernel (``q_new = q + h q'_new``). The URDF
gives the limits (rad or m) and the joint damping. Not a section of the robot spec: its settings
are the ``integrator`` table's ``end_stop_*``.
"""

import math

from numba import njit

from ..kernel.layout import DP, col

LOWER, UPPER, STOP_K, STOP_C, DAMPING, ACT, LOCKED = DP.declare(
    "joint",
    col("LOWER", "rad or m", "joint lower limit"),
    col("UPPER", "rad or m", "joint upper limit"),
    col("STOP_K", "N m/rad or N/m", "end-stop stiffness"),
    col("STOP_C", "N m s/rad or N s/m", "end-stop damping"),
    col("DAMPING", "N m s/rad or N s/m", "viscous joint damping"),
    col("ACT", "-", "index of the actuator driving the joint, -1 if passive"),
    col("LOCKED", "-", "1.0: joint held rigid at its current position, its actuator not simulated"),
)


def lower_joint(DP_, i, lower, upper, damping, inertia, tau_max, integ, actuator) -> None:
    """End stops from the link inertia (kg m^2 or kg) and the actuator's largest force ``tau_max``."""
    w = 2.0 * math.pi * integ["end_stop_frequency"]
    k = max(inertia * w * w, tau_max / integ["end_stop_penetration"])
    DP_[i, LOWER] = lower
    DP_[i, UPPER] = upper
    DP_[i, STOP_K] = k
    DP_[i, STOP_C] = 2.0 * integ["end_stop_damping_ratio"] * math.sqrt(k * inertia)
    DP_[i, DAMPING] = damping
    DP_[i, ACT] = actuator


@njit(inline="always")
def joint_forces(i, q, qd, DP):
    """Damping and end-stop forces on joint ``i``: (damping force, stop force, slope -d/dqd of
    both, stop stiffness while in contact)."""
    damp = -(DP[i, DAMPING] * qd)
    dlin = DP[i, DAMPING]
    stop = 0.0
    kst = 0.0
    lo = DP[i, LOWER]
    hi = DP[i, UPPER]
    if q > hi:  # end stop: spring-damper while penetrating, never pulling
        f = -DP[i, STOP_K] * (q - hi) - DP[i, STOP_C] * qd
        if f < 0.0:
            stop = f
            dlin += DP[i, STOP_C]
            kst = DP[i, STOP_K]
    elif q < lo:
        f = -DP[i, STOP_K] * (q - lo) - DP[i, STOP_C] * qd
        if f > 0.0:
            stop = f
            dlin += DP[i, STOP_C]
            kst = DP[i, STOP_K]
    return damp, stop, dlin, kst


@njit(inline="always")
def stop_force(i, q, qd, DP):
    """End-stop force alone (reference solver)."""
    if q > DP[i, UPPER]:
        f = -DP[i, STOP_K] * (q - DP[i, UPPER]) - DP[i, STOP_C] * qd
        if f < 0.0:
            return f
    elif q < DP[i, LOWER]:
        f = -DP[i, STOP_K] * (q - DP[i, LOWER]) - DP[i, STOP_C] * qd
        if f > 0.0:
            return f
    return 0.0


def stop_energy(DP_, q) -> float:
    """Energy stored in end-stop springs (J)."""
    e = 0.0
    for i in range(q.size):
        if q[i] > DP_[i, UPPER]:
            e += 0.5 * DP_[i, STOP_K] * (q[i] - DP_[i, UPPER]) ** 2
        elif q[i] < DP_[i, LOWER]:
            e += 0.5 * DP_[i, STOP_K] * (q[i] - DP_[i, LOWER]) ** 2
    return e
