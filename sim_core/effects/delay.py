from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


class Delay(Effect):
    """Transport delay of the valve command (bus, amplifier processing, pilot stage).

    u_d(t) = u(t - d). The whole response shifts later by d without changing its shape; the
    residual against an undelayed model is about -d times the joint velocity. The kernel averages
    the delayed command over each substep, which makes the delay fractional and smooth in d.
    """

    name = "delay"
    citation = CITE_CATALOG + " (§3.3)"
    PARAMETERS = (Parameter("delay", "s", "dead time between command and amplifier", 0.03, 0.0, 0.3),)

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_E_DELAY] = 1.0
        lw.AP[a, L.AP_DELAY] = params["delay"]
