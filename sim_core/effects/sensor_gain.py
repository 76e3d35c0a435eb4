from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, col
from .base import CITE_CATALOG, Effect

SENS_GAIN = AP.declare("sensor_gain", col("SENS_GAIN", "-", "multiplies the sensed position (1 when off)"))


class SensorGain(Effect):
    """Potentiometer gain error: the measured angle is scaled (calibration A wrong).

    y = g q. The residual is proportional to the angle itself, identical in holds and in motion.
    """

    name = "sensor_gain"
    citation = CITE_CATALOG + " (§3.10)"
    PARAMETERS = (Parameter("gain", "-", "multiplies the measured angle", 1.03, 0.5, 1.5),)
    requires_sensor = True
    switch = False          # always applied; 1.0 when off
    HOOKS = {"sensor_position": "scaled_position"}
    ORDER = 1
    CONFUSIONS = {
        "payload": "a static calibration of the angle sensor against an inclinometer",
        "sensor_offset": "a record over a wider angle range, through zero (an offset is the same at every angle, a gain error grows with the angle)",
    }

    @classmethod
    def lower_neutral(cls, lw, a):
        lw.AP[a, SENS_GAIN] = 1.0

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, SENS_GAIN] = params["gain"]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        grid = [[min(max(guess["gain"], 0.55), 1.45)]] if "gain" in guess else []
        null = current["gain"] if current else 1.0
        return {"free": [("gain", 0.5, 1.5, False, null, "")], "fixed": {"gain": (current or {}).get("gain", 1.0)}, "grid": grid}

    @classmethod
    def signature_guess(cls, sig, context):
        g = sig.get("sensor_gain")
        return {"gain": float(g)} if g is not None else None


@njit(inline="always")
def scaled_position(th, a, q_dof, AP, XS):
    return AP[a, SENS_GAIN] * th
