from numba import njit

from ..components.base import Parameter
from ..components.spool import LAG_TAU, LAG_X
from .base import CITE_JELALI, Effect


class SpoolLag(Effect):
    """Slower spool or amplifier: an extra first-order lag between spool and metering position.

    tau x_lag' = x - x_lag; the valve meters with x_lag. Phase lag grows with frequency and the
    magnitude rolls off above 1/(2 pi tau): the joint starts and stops later and overshoots less.
    The lag state is part of the spool's linear command chain (integrated exactly with it).
    """

    name = "spool_lag"
    citation = CITE_JELALI + ", sec. 3.3"
    PARAMETERS = (Parameter("time_constant", "s", "time constant of the extra lag", 0.05, 0.002, 0.5),)
    HOOKS = {"metering": "lagged_spool_position"}
    CONFUSIONS = {"backlash": "slow reversals at several speeds"}

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, LAG_TAU] = params["time_constant"]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        null = current["time_constant"] if current else 0.0
        return {"free": [("time_constant", 0.002, 0.5, True, null, "s")],
                "grid": [[v] for v in (0.005, 0.015, 0.04, 0.1, 0.25)]}


@njit(inline="always")
def lagged_spool_position(a, AP, XS):
    return XS[a, LAG_X]
