"""Hydraulic fluid properties."""

from ..kernel.layout import GP, col
from .base import Component, Parameter

P_ATM = 101325.0  # Pa

BETA, P_MIN, ATM = GP.declare(
    "fluid",
    col("BETA", "Pa", "oil bulk modulus"),
    col("P_MIN", "Pa", "cavitation floor (gauge)"),
    col("P_ATM", "Pa", "atmospheric pressure"),
)


class Fluid(Component):
    """Hydraulic oil: density, bulk modulus, viscosity, cavitation floor.

    Chamber pressures follow the continuity equation with a constant bulk modulus,

        (V / beta) dp/dt = Q_in - dV/dt,

    i.e. the fluid is the exponential-density liquid rho = rho_0 exp(p / beta) (Merritt 1967, §2).
    The ``bulk_modulus`` effect makes beta pressure dependent (entrained air). Pressures are gauge
    pressures; the cavitation floor keeps a chamber from going below vapour pressure.
    """

    section = "fluid"
    citation = "H. E. Merritt, Hydraulic Control Systems, Wiley, 1967, ch. 2"
    PARAMETERS = (
        Parameter("density", "kg/m^3", "oil density", None, 600.0, 1200.0),
        Parameter("bulk_modulus", "Pa", "effective bulk modulus of the oil in rigid chambers", None, 1e7, 3e9),
        Parameter("kinematic_viscosity", "m^2/s", "kinematic viscosity at working temperature", None, 1e-7, 1e-3),
        Parameter("cavitation_pressure", "Pa", "gauge pressure floor (vapour pressure minus atmosphere)", -0.095e6, -0.1013e6, 0.0),
    )

    @property
    def dynamic_viscosity(self) -> float:
        return self.values["density"] * self.values["kinematic_viscosity"]

    def lower_global(self, lw, spec):
        lw.GP[BETA] = self["bulk_modulus"]
        lw.GP[P_MIN] = self["cavitation_pressure"]
        lw.GP[ATM] = P_ATM
