"""Proportional valve amplifier (voltage in, solenoid current reference out)."""

from numba import njit

from ..kernel.layout import AP, col
from .base import Component, Parameter
from .labview_adaptation import CITATION_MARS_ND

AMP_GAIN, AMP_IMAX = AP.declare(
    "amplifier",
    col("AMP_GAIN", "A/V", "amplifier transconductance"),
    col("AMP_IMAX", "A", "amplifier current limit"),
)


class Amplifier(Component):
    """Current-output valve amplifier with saturation, one per solenoid (A and B).

        i_ref = min(K_a * v, I_max),   v >= 0

    The proportional amplifier of Fig. 8 of Montazeri & Ekotuyo is a gain with a limit; the
    current loop it closes around the coil is the solenoid's first-order lag (see
    ``proportional_solenoid``).
    """

    section = "amplifier"
    citation = CITATION_MARS_ND
    PARAMETERS = (
        Parameter("gain", "A/V", "transconductance: solenoid current per volt of command", None, 0.0, 10.0),
        Parameter("max_current", "A", "current limit of the output stage", None, 0.0, 10.0),
    )

    def lower(self, lw, a, spec, js):
        lw.AP[a, AMP_GAIN] = self["gain"]
        lw.AP[a, AMP_IMAX] = self["max_current"]


@njit(inline="always")
def amplifier_current(v, gain, imax):
    """Reference current (A) for a unipolar input ``v`` (V)."""
    i = gain * v
    if i > imax:
        return imax
    return i
