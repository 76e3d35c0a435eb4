"""Joint angle sensor: potentiometer (HydroLek) or resolver interface (harvester)."""

from .base import Component, Parameter
from .labview_adaptation import CITATION_MARS_ND


class Potentiometer(Component):
    """Linear angle sensor read by a cFP analog input.

        angle = A * raw + B          (Montazeri & Ekotuyo, Sec. II-C)
        raw   = clip(q(quantise((theta - B) / A + noise)), v_min, v_max)

    ``A`` and ``B`` are the calibration the operator's VI uses. The ADC quantises to ``bits`` over
    the input range; ``noise`` is the wiper/ADC noise in volts. Calibration errors are the
    ``sensor_gain`` and ``sensor_offset`` effects; lost motion in the coupling is ``backlash``.
    """

    section = "sensor"
    citation = CITATION_MARS_ND
    PARAMETERS = (
        Parameter("A", "rad/V", "calibration gain", None, -100.0, 100.0),
        Parameter("B", "rad", "calibration offset", None, -100.0, 100.0),
        Parameter("noise", "V", "standard deviation of the voltage noise", 0.0, 0.0, 1.0),
        Parameter("bits", "-", "ADC resolution over the input range (0: no quantisation)", 16.0, 0.0, 24.0),
        Parameter("range", "V", "ADC input range [min, max]", (0.0, 10.0), kind="vec", length=2),
    )
