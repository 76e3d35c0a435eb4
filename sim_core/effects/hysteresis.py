from numba import njit

from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


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

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_E_HYST] = 1.0
        lw.AP[a, L.AP_HYST_WIDTH] = params["width"]


@njit(cache=True, inline="always")
def play(state, u, half_width):
    """Play (backlash) operator: new output for input ``u``."""
    if u - state > half_width:
        return u - half_width
    if state - u > half_width:
        return u + half_width
    return state
