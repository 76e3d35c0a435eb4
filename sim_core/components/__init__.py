"""Hydraulic, electrical and sensing components of a valve-controlled joint.

Each module holds one component: its parameters (declared with units and bounds, values from the
robot spec), the equations it implements (docstring, with a citation), the kernel columns it owns
and those equations compiled for the kernel. ``chambers`` and ``joint`` are parts of every joint
that have no section in the spec (their settings come from other sections and the URDF).
Actuator kinds (``ACTUATOR_KINDS``) give the kernel their force, geometry and cached quantities.
"""

from . import chambers, joint  # noqa: F401 - declare their kernel columns
from .amplifier import Amplifier
from .base import Component, Parameter, ParameterError
from .cylinder import Cylinder
from .directional_valve import DirectionalValve
from .fluid import Fluid
from .hose import Hose
from .labview_adaptation import LabviewAdaptation
from .links import LinkMasses
from .potentiometer import Potentiometer
from .proportional_solenoid import ProportionalSolenoid
from .pump import Pump
from .rotary_actuator import RotaryActuator
from .spool import Spool

# actuator kinds in the order of their kernel id (AP_KIND)
ACTUATOR_KINDS = (Cylinder, RotaryActuator)

__all__ = [
    "ACTUATOR_KINDS", "Amplifier", "Component", "Cylinder", "DirectionalValve", "Fluid", "Hose", "LabviewAdaptation",
    "LinkMasses", "Parameter", "ParameterError", "Potentiometer", "ProportionalSolenoid", "Pump", "RotaryActuator", "Spool",
]
