"""Hydraulic hose between a valve port and an actuator chamber."""

import math

from .base import Component, Parameter

CITATION_HOSE = (
    "E. Papadopoulos, B. Mu, R. Frenette, IEEE/ASME T-Mech 8(2), 2003, Sec. III-c and Fig. 6; "
    "J. Watton, Fundamentals of Fluid Power Control, Cambridge, 2009, ch. 5"
)


class Hose(Component):
    """Hose as a T-type lumped line: capacitance at the valve end, then inertance and resistance.

        C_h dp_h/dt = Q_valve - q          C_h = V_h / beta_h,   V_h = pi d^2 l / 4
        I dq/dt     = p_h - p_chamber - R(q)   I = rho l / a,    a = pi d^2 / 4
        R(q) = R_lam q                      R_lam = 128 mu l / (pi d^4)        (laminar)
        R(q) = R_turb q |q|                 R_turb = lambda l rho / (2 d a^2)  (turbulent, Darcy)

    One lump suffices while the observed line oscillation is far below the quarter-wave frequency
    c/(4 l) (Papadopoulos et al., eq. (3): ~3 Hz against ~214 m/s / 4 l). The line dynamics are
    switched on by the ``line_dynamics`` effect; otherwise the hose only adds its volume, with its
    own compliance, to the chamber. ``effective_bulk_modulus`` combines oil and wall elasticity
    (rubber SAE 100R12 hose: roughly half the oil's value).
    """

    section = "hose"
    citation = CITATION_HOSE
    PARAMETERS = (
        Parameter("length", "m", "hose length, valve to actuator", None, 0.0, 50.0),
        Parameter("inner_diameter", "m", "hose bore", None, 1e-3, 0.1),
        Parameter("flow_regime", "-", "resistance law of the line", "turbulent", kind="choice", choices=("laminar", "turbulent")),
        Parameter("effective_bulk_modulus", "Pa", "bulk modulus of the oil-filled hose incl. wall expansion", 7.0e8, 1e7, 3e9),
        Parameter("friction_factor", "-", "Darcy friction factor for the turbulent law (Blasius at Re ~ 3000-10000)", 0.04, 0.005, 0.2),
    )

    @property
    def area(self) -> float:
        return math.pi * self.values["inner_diameter"] ** 2 / 4.0

    @property
    def volume(self) -> float:
        return self.area * self.values["length"]

    def inertance(self, density: float) -> float:
        return density * self.values["length"] / self.area

    def laminar_resistance(self, dynamic_viscosity: float) -> float:
        return 128.0 * dynamic_viscosity * self.values["length"] / (math.pi * self.values["inner_diameter"] ** 4)

    def turbulent_resistance(self, density: float) -> float:
        d, l = self.values["inner_diameter"], self.values["length"]
        return self.values["friction_factor"] * l * density / (2.0 * d * self.area ** 2)
