from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


class SensorGain(Effect):
    """Potentiometer gain error: the measured angle is scaled (calibration A wrong).

    y = g q. The residual is proportional to the angle itself, identical in holds and in motion.
    """

    name = "sensor_gain"
    citation = CITE_CATALOG + " (§3.10)"
    PARAMETERS = (Parameter("gain", "-", "multiplies the measured angle", 1.03, 0.5, 1.5),)
    requires_sensor = True

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_SENS_GAIN] = params["gain"]
