from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, col
from .base import CITE_CATALOG, Effect

SENS_OFFSET = AP.declare("sensor_offset", col("SENS_OFFSET", "rad or m", "added to the sensed position (0 when off)"))


class SensorOffset(Effect):
    """Potentiometer offset: the measured angle is shifted by a constant (calibration B wrong).

    y = q + c. The residual is the same constant in holds and in motion; dynamics are unchanged.
    """

    name = "sensor_offset"
    citation = CITE_CATALOG + " (§3.10)"
    PARAMETERS = (Parameter("offset", "rad or m", "added to the measured angle (position in m on a prismatic joint)", 0.02, -0.5, 0.5),)
    requires_sensor = True
    switch = False          # always applied; 0.0 when off
    HOOKS = {"sensor_position": "shifted_position"}
    ORDER = 2

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, SENS_OFFSET] = params["offset"]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        grid = [[guess["offset"]]] if "offset" in guess else []
        null = current["offset"] if current else 0.0
        return {"free": [("offset", -0.5, 0.5, False, null, "rad")], "fixed": {"offset": (current or {}).get("offset", 0.0)}, "grid": grid}

    @classmethod
    def signature_guess(cls, sig, context):
        o = sig.get("sensor_offset")
        return {"offset": float(o)} if o is not None else None


@njit(inline="always")
def shifted_position(th, a, q_dof, AP, XS):
    return th + AP[a, SENS_OFFSET]
