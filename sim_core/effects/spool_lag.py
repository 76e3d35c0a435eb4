from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_JELALI, Effect


class SpoolLag(Effect):
    """Slower spool or amplifier: an extra first-order lag between spool and metering position.

    tau x_lag' = x - x_lag; the valve meters with x_lag. Phase lag grows with frequency and the
    magnitude rolls off above 1/(2 pi tau): the joint starts and stops later and overshoots less.
    """

    name = "spool_lag"
    citation = CITE_JELALI + ", sec. 3.3"
    PARAMETERS = (Parameter("time_constant", "s", "time constant of the extra lag", 0.05, 0.002, 0.5),)

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_E_SPOOL_LAG] = 1.0
        lw.AP[a, L.AP_LAG_TAU] = params["time_constant"]
