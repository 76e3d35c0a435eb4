from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


class SensorOffset(Effect):
    """Potentiometer offset: the measured angle is shifted by a constant (calibration B wrong).

    y = q + c. The residual is the same constant in holds and in motion; dynamics are unchanged.
    """

    name = "sensor_offset"
    citation = CITE_CATALOG + " (§3.10)"
    PARAMETERS = (Parameter("offset", "rad", "added to the measured angle", 0.02, -0.5, 0.5),)
    requires_sensor = True

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_SENS_OFFSET] = params["offset"]
