"""Joint angle sensor: potentiometer (HydroLek) or resolver interface (harvester)."""

import math

import numpy as np
from numba import njit

from ..kernel.layout import AP, XS, col
from .base import Component, Parameter
from .labview_adaptation import CITATION_MARS_ND

SENSED, POT_A, POT_B, POT_NOISE, POT_LSB, POT_VMIN, POT_VMAX = AP.declare(
    "sensor",
    col("SENSED", "-", "1.0 if a potentiometer/resolver measures the joint"),
    col("POT_A", "rad/V or m/V", "calibration: position = A * raw + B"),
    col("POT_B", "rad or m", "calibration offset"),
    col("POT_NOISE", "V", "sensor voltage noise, standard deviation"),
    col("POT_LSB", "V", "ADC quantisation step; 0 = none"),
    col("POT_VMIN", "V", "ADC input range, lower end"),
    col("POT_VMAX", "V", "ADC input range, upper end"),
)
F_SENS_MODE, F_SENS_VALUE, F_SENS_NOISE, F_SENS_OFFSET = AP.declare(
    "sensor",
    col("F_SENS_MODE", "-", "fault: 0 none, 1 stuck, 2 noisy"),
    col("F_SENS_VALUE", "V", "fault: stuck sensor voltage"),
    col("F_SENS_NOISE", "V", "fault: extra sensor noise"),
    col("F_SENS_OFFSET", "V", "fault: sensor voltage offset"),
)
SENS_V, SENS_ANGLE = XS.declare(
    "sensor",
    col("SENS_V", "V", "last sensor voltage"),
    col("SENS_ANGLE", "rad or m", "last calibrated position A v + B"),
)


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
    FAULTS = ("sensor_stuck", "sensor_noisy", "sensor_offset")

    def lower(self, lw, a, spec, js):
        vmin, vmax = self["range"]
        AP_ = lw.AP
        AP_[a, SENSED] = 1.0
        AP_[a, POT_A] = self["A"]
        AP_[a, POT_B] = self["B"]
        AP_[a, POT_NOISE] = self["noise"]
        AP_[a, POT_LSB] = (vmax - vmin) / 2.0 ** self["bits"] if self["bits"] > 0 else 0.0
        AP_[a, POT_VMIN], AP_[a, POT_VMAX] = vmin, vmax

    @staticmethod
    def lower_fault(lw, a, kind, mode):
        AP_ = lw.AP
        if kind == "sensor_stuck":
            AP_[a, F_SENS_MODE] = 1.0
            AP_[a, F_SENS_VALUE] = float(mode["value"])
        elif kind == "sensor_noisy":
            AP_[a, F_SENS_MODE] = 2.0
            AP_[a, F_SENS_NOISE] = float(mode.get("std", 0.05))
        else:
            AP_[a, F_SENS_OFFSET] = float(mode.get("offset", 0.2))


@njit(inline="always")
def _next_uniform(rng):
    # xorshift64* (Vigna 2016): deterministic, seedable, no global state
    x = rng[0]
    x ^= x >> np.uint64(12)
    x ^= x << np.uint64(25)
    x ^= x >> np.uint64(27)
    rng[0] = x
    r = x * np.uint64(2685821657736338717)
    return ((r >> np.uint64(11)) + np.uint64(1)) * (1.0 / 9007199254740994.0)


@njit
def gauss(rng):
    """Standard normal deviate (Box-Muller)."""
    u1 = _next_uniform(rng)
    u2 = _next_uniform(rng)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@njit(inline="always")
def read_sensor(a, th, AP, XS, rng):
    """The cFP analog input of a joint at position ``th`` (what the sensor sees): voltage with noise,
    faults, quantisation and range, and the calibrated position A v + B."""
    A = AP[a, POT_A]
    B = AP[a, POT_B]
    v = (th - B) / A
    if AP[a, POT_NOISE] > 0.0:
        v += AP[a, POT_NOISE] * gauss(rng)
    mode = AP[a, F_SENS_MODE]
    if mode == 1.0:
        v = AP[a, F_SENS_VALUE]
    elif mode == 2.0:
        v += AP[a, F_SENS_NOISE] * gauss(rng)
    v += AP[a, F_SENS_OFFSET]
    lsb = AP[a, POT_LSB]
    vmin = AP[a, POT_VMIN]
    vmax = AP[a, POT_VMAX]
    if lsb > 0.0:
        v = vmin + math.floor((v - vmin) / lsb + 0.5) * lsb
    if v < vmin:
        v = vmin
    elif v > vmax:
        v = vmax
    XS[a, SENS_V] = v
    XS[a, SENS_ANGLE] = A * v + B
    return v, A * v + B
