from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, XS, col
from .base import CITE_CATALOG, Effect

HYST_WIDTH = AP.declare("hysteresis", col("HYST_WIDTH", "V", "full width of the play operator"))
U_HYST = XS.declare("hysteresis", col("U_HYST", "V", "play-operator state (follows the command when off)"))


class Hysteresis(Effect):
    """Proportional-solenoid hysteresis: a play operator of the given loop width on the command.

    u_h <- clip(u_h, u - w/2, u + w/2). The valve opening depends on the direction the command came
    from: after the command returns to 0 the spool stays open by up to w/2 in the direction of the
    previous motion, so the joint keeps creeping that way; small reversals inside the loop do
    nothing. Proportional-solenoid valves show 3-5 % hysteresis without dither (below 1 % with).
    """

    name = "hysteresis"
    citation = "M. Jelali, A. Kroll, Hydraulic Servo-systems, Springer, 2003, sec. 3.2; " + CITE_CATALOG + " (§3.2)"
    PARAMETERS = (Parameter("width", "V", "full width of the hysteresis loop in command volts", 0.4, 0.0, 3.0),)
    HOOKS = {"command": "hysteresis_command", "command_off": "hysteresis_track"}
    ORDER = 1
    CONFUSIONS = {"leakage": "holds after commands of both signs (hysteresis creeps the previous way, leakage follows the load)"}

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, HYST_WIDTH] = params["width"]

    @classmethod
    def reference_command(cls, u, a, AP_, XS_, memory):
        state = memory.get("u_hyst", XS_[a, U_HYST])
        state = play(state, u, 0.5 * AP_[a, HYST_WIDTH])
        memory["u_hyst"] = state
        return state

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        null = current["width"] if current else 0.0
        return {"free": [("width", 0.0, 3.0, False, null, "V")],
                "grid": [[v] for v in (0.1, 0.25, 0.45, 0.7, 1.0, 1.5, 2.2)]}


@njit(inline="always")
def play(state, u, half_width):
    """Play (backlash) operator: new output for input ``u``."""
    if u - state > half_width:
        return u - half_width
    if state - u > half_width:
        return u + half_width
    return state


@njit(inline="always")
def hysteresis_command(u, a, t, h, AP, XS, XG, HT, HU):
    u = play(XS[a, U_HYST], u, 0.5 * AP[a, HYST_WIDTH])
    XS[a, U_HYST] = u
    return u


@njit(inline="always")
def hysteresis_track(u, a, AP, XS):
    XS[a, U_HYST] = u
