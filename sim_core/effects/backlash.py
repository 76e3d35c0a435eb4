from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, XS, col
from .base import CITE_CATALOG, Effect, clip_grid
from .hysteresis import play

BACK_WIDTH = AP.declare("backlash", col("BACK_WIDTH", "rad or m", "total play"))
Y_BACK = XS.declare("backlash", col("Y_BACK", "rad or m", "play-operator state: where the sensor sees the joint"))


class Backlash(Effect):
    """Lost motion between the joint and its sensor (worn pins, loose coupling): a play operator.

    y_b <- clip(y_b, q - b/2, q + b/2) is what the potentiometer sees. At every reversal the
    measured angle stands still until the joint has crossed the play b, so the measured motion
    lags the true motion by b/2 in the direction of travel, independent of speed.
    """

    name = "backlash"
    citation = CITE_CATALOG + " (§3.9)"
    PARAMETERS = (Parameter("width", "rad or m", "total play (m on a prismatic joint)", 0.01, 0.0, 0.2),)
    requires_sensor = True
    HOOKS = {"sensor_position": "sensed_through_play", "after_substep": "advance_play", "after_substep_off": "track_joint"}
    ORDER = 0

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, BACK_WIDTH] = params["width"]

    @classmethod
    def reset(cls, ctx, a, q_dof, tau, on):
        ctx.XS[a, Y_BACK] = q_dof

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        grid = [0.002, 0.005, 0.01, 0.02, 0.04, 0.08, 0.15]
        if "width" in guess:
            grid.append(guess["width"])
        null = current["width"] if current else 0.0
        return {"free": [("width", 1e-4, 0.2, True, null, "rad")], "grid": [[v] for v in clip_grid(grid, 1e-4, 0.2)]}

    @classmethod
    def signature_guess(cls, sig, context):
        hw = sig.get("backlash_half_width")
        return {"width": float(2 * hw)} if hw is not None and hw > 0 else None


@njit(inline="always")
def sensed_through_play(th, a, q_dof, AP, XS):
    return XS[a, Y_BACK]


@njit(inline="always")
def advance_play(a, q_dof, AP, XS):
    XS[a, Y_BACK] = play(XS[a, Y_BACK], q_dof, 0.5 * AP[a, BACK_WIDTH])


@njit(inline="always")
def track_joint(a, q_dof, AP, XS):
    XS[a, Y_BACK] = q_dof
