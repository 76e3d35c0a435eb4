"""Proportional solenoid: coil current dynamics."""

from ..kernel.layout import AP, col
from .base import Component, Parameter
from .labview_adaptation import CITATION_MARS_ND

SOL_TAU = AP.declare("solenoid", col("SOL_TAU", "s", "solenoid current time constant"))


class ProportionalSolenoid(Component):
    """Proportional solenoid with a current-controlled coil.

        tau_s di/dt = i_ref - i

    The coil inductance against the amplifier's current loop gives a first-order lag with time
    constant ``tau_s`` (L/R of the coil divided by the loop gain; a few ms for 24 V proportional
    solenoids). The solenoid force is proportional to the current and drives the spool (see
    ``spool``). Montazeri & Ekotuyo, Fig. 9; Jelali & Kroll, *Hydraulic Servo-systems*, 2003, §3.2.
    """

    section = "solenoid"
    citation = CITATION_MARS_ND + "; M. Jelali, A. Kroll, Hydraulic Servo-systems, Springer, 2003, sec. 3.2"
    PARAMETERS = (
        Parameter("time_constant", "s", "current rise time constant of the coil with its amplifier", None, 1e-4, 0.2),
    )

    def lower(self, lw, a, spec, js):
        lw.AP[a, SOL_TAU] = self["time_constant"]
