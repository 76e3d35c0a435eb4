"""Hydraulic rotary actuator (vane) or motor with a gear."""

from .base import Component, Parameter

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
