"""Hydraulic hose between a valve port and an actuator chamber."""

import math

from numba import njit

from ..kernel.layout import AP, col
from .base import Component, Parameter
from .directional_valve import DP_TR, orifice

HOSE_VOL, HOSE_BETA, HOSE_I, HOSE_RLAM, HOSE_RTURB, HOSE_TURB = AP.declare(
    "hose",
    col("HOSE_VOL", "m^3", "volume of one hose"),
    col("HOSE_BETA", "Pa", "effective bulk modulus of oil in the hose incl. wall compliance"),
    col("HOSE_I", "kg/m^4", "hose fluid inertance rho l / a"),
    col("HOSE_RLAM", "Pa s/m^3", "laminar hose resistance 128 mu l / (pi d^4)"),
    col("HOSE_RTURB", "Pa s^2/m^6", "turbulent hose resistance, dp = R q |q|"),
    col("HOSE_TURB", "-", "1.0 turbulent, 0.0 laminar"),
)
F_BURST_KV = AP.declare("hose", col("F_BURST_KV", "m^3/s/sqrt(Pa)", "fault: hose burst, orifice to tank on line A"))

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

    FAULTS = ("hose_burst",)

    def lower(self, lw, a, spec, js):
        AP_ = lw.AP
        fluid = spec.fluid
        AP_[a, HOSE_VOL] = max(self.volume, 1e-9)  # a zero-length hose still has a port volume
        AP_[a, HOSE_BETA] = self["effective_bulk_modulus"]
        AP_[a, HOSE_I] = self.inertance(fluid["density"])
        AP_[a, HOSE_RLAM] = self.laminar_resistance(fluid.dynamic_viscosity)
        AP_[a, HOSE_RTURB] = self.turbulent_resistance(fluid["density"])
        AP_[a, HOSE_TURB] = 1.0 if self["flow_regime"] == "turbulent" else 0.0

    @staticmethod
    def lower_fault(lw, a, kind, mode):
        from .directional_valve import DP_RATED, FLOW_EXP, KV

        # default: a rupture passing 5x the valve's rated flow at its rated drop (a sqrt-law orifice)
        kv, n, dp = lw.AP[a, KV], lw.AP[a, FLOW_EXP], lw.AP[a, DP_RATED]
        kv_sqrt = kv if n == 0.5 else kv * dp ** n / math.sqrt(dp)
        lw.AP[a, F_BURST_KV] = float(mode.get("flow_coefficient", 5.0 * kv_sqrt))


@njit(inline="always")
def burst_flow(a, ua, p_t, AP):
    """Fault 'hose_burst': flow (m^3/s) out of line A through the rupture, and its slope."""
    kb = AP[a, F_BURST_KV]
    if kb > 0.0:
        fb, db = orifice(ua - p_t, AP[a, DP_TR])
        return kb * fb, kb * db
    return 0.0, 0.0


@njit(inline="always")
def lumped_pressures(a, h, ua, ub, pa, pb, qva, dqva, qvb, dqvb, va, vb, qdisp_a, qdisp_b,
                     lk_a, dlk_a, lk_b, dlk_b, beta0, bulk, GP, AP, XS, XG, energy):
    """Chamber plus hose as one node per side, linearly implicit in the node's own pressure:
    p += h (Q_valve - Q_disp - Q_leak) / (C - h dQ/dp),  C = V/beta + V_h/beta_h.
    Returns the new chamber and valve-port pressures (the same here)."""
    fa = bulk(pa, GP)
    fb = bulk(pb, GP)
    vh = AP[a, HOSE_VOL]
    beta_h = AP[a, HOSE_BETA]
    ca = va / (beta0 * fa) + vh / (beta_h * fa)
    cb = vb / (beta0 * fb) + vh / (beta_h * fb)
    pa_n = pa + h * (qva - qdisp_a - lk_a) / (ca - h * (dqva - dlk_a))
    pb_n = pb + h * (qvb - qdisp_b - lk_b) / (cb - h * (dqvb - dlk_b))
    return pa_n, pb_n, pa_n, pb_n, fa, fb


@njit(inline="always")
def lumped_derivatives(a, pa, pb, qva, qvb, va, vb, qdisp_a, qdisp_b, lk_a, lk_b, beta0, bulk, GP, AP, XS, dXS):
    """Reference solver: dp/dt of the lumped chamber-plus-hose nodes."""
    fa = bulk(pa, GP)
    fb = bulk(pb, GP)
    vh = AP[a, HOSE_VOL]
    bh = AP[a, HOSE_BETA]
    ca = va / (beta0 * fa) + vh / (bh * fa)
    cb = vb / (beta0 * fb) + vh / (bh * fb)
    return (qva - qdisp_a - lk_a) / ca, (qvb - qdisp_b - lk_b) / cb
