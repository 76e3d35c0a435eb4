from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


class Backlash(Effect):
    """Lost motion between the joint and its sensor (worn pins, loose coupling): a play operator.

    y_b <- clip(y_b, q - b/2, q + b/2) is what the potentiometer sees. At every reversal the
    measured angle stands still until the joint has crossed the play b, so the measured motion
    lags the true motion by b/2 in the direction of travel, independent of speed.
    """

    name = "backlash"
    citation = CITE_CATALOG + " (§3.9)"
    PARAMETERS = (Parameter("width", "rad", "total play", 0.01, 0.0, 0.2),)
    requires_sensor = True

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_E_BACKLASH] = 1.0
        lw.AP[a, L.AP_BACK_WIDTH] = params["width"]
