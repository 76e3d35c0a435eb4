"""Hydraulic rotary actuator (vane) or motor with a gear."""

from numba import njit

from .base import Component, Parameter
from .chambers import AREA_A, AREA_B, P_A, P_B, VDEAD_A, VDEAD_B, VISC, lower_relief

CITATION_ROTARY = (
    "E. Papadopoulos et al., IEEE/ASME T-Mech 8(2), 2003, Sec. III-e (swing motor as a two-port "
    "gyrator, laminar internal/external leakage); H. E. Merritt, Hydraulic Control Systems, 1967, ch. 5"
)


class RotaryActuator(Component):
    """Rotary vane actuator or fixed-displacement motor driving the joint through a gear.

        tau_joint = N D (p_A - p_B) - b q'        flows: Q_disp = N D q'
        C_A dp_A/dt = Q_A - N D q' - Q_leak,      C_B dp_B/dt = Q_B + N D q' + Q_leak

    ``D`` is the displacement (m^3/rad at the actuator shaft), ``N`` the gear ratio (actuator turns
    per joint turn). Chamber volumes are constant. Internal (cross-port) and external leakage are
    the ``leakage`` effect (on by default for the harvester swing motor, as in the paper).
    """

    section = "rotary"
    citation = CITATION_ROTARY
    PARAMETERS = (
        Parameter("type", "-", "vane actuator (limited angle) or hydraulic motor", "vane", kind="choice", choices=("vane", "motor")),
        Parameter("displacement", "m^3/rad", "displacement per radian of the actuator shaft", None, 1e-9, 1e-2),
        Parameter("gear_ratio", "-", "actuator shaft turns per joint turn", 1.0, 1e-3, 1e4),
        Parameter("chamber_volume", "m^3", "volume of each chamber incl. ports", None, 1e-8, 1.0),
        Parameter("viscous_friction", "N m s/rad", "viscous friction referred to the joint", 0.0, 0.0, 1e8),
        Parameter("port_relief_pressure", "Pa", "cross-port relief cracking pressure; 0 = none", 0.0, 0.0, 1e8),
    )

    KIND = "rotary"
    KERNEL = {"prime": "rotary_prime", "force": "rotary_force", "geometry": "rotary_geometry"}

    @staticmethod
    def holding_pressures(AP_row, th, tau, pm):
        """Chamber pressures (Pa) symmetric about ``pm`` that hold joint torque ``tau``."""
        dp = tau / AP_row[AREA_A]
        return pm + 0.5 * dp, pm - 0.5 * dp

    @staticmethod
    def max_force(AP_row, lower, upper, p_supply):
        """Joint torque at full supply pressure (N m)."""
        return p_supply * AP_row[AREA_A]

    def lower(self, lw, a, spec, js):
        AP_ = lw.AP
        AP_[a, AREA_A] = AP_[a, AREA_B] = self["gear_ratio"] * self["displacement"]
        AP_[a, VDEAD_A] = AP_[a, VDEAD_B] = self["chamber_volume"]
        AP_[a, VISC] = self["viscous_friction"]
        lower_relief(lw, a, self["port_relief_pressure"], js.components["valve"]["rated_flow"])

    @staticmethod
    def chamber_volumes(AP_row, th):
        return AP_row[VDEAD_A], AP_row[VDEAD_B]


@njit(inline="always")
def rotary_prime(a, th, AP, XS):
    """Nothing to cache: the geometry does not depend on the angle."""


@njit(inline="always")
def rotary_force(a, AP, XS):
    """Joint torque N D (p_A - p_B) (N m) and the viscous friction at the joint (N m s/rad)."""
    return (XS[a, P_A] - XS[a, P_B]) * AP[a, AREA_A], AP[a, VISC]


@njit(inline="always")
def rotary_geometry(a, th, om, AP, XS):
    """Constant chamber volumes (m^3), displaced flows N D q' (m^3/s), no volume change."""
    return AP[a, VDEAD_A], AP[a, VDEAD_B], AP[a, AREA_A] * om, -AP[a, AREA_A] * om, 0.0, 0.0
