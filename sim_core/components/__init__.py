"""Hydraulic, electrical and sensing components of a valve-controlled joint.

Each module holds one component: its parameters (declared with units and bounds, values from the
robot spec), the equations it implements (docstring, with a citation) and those equations compiled
for the kernel.
"""

from .amplifier import Amplifier
from .base import Component, Parameter, ParameterError
from .cylinder import Cylinder
from .directional_valve import DirectionalValve
from .fluid import Fluid
from .hose import Hose
from .labview_adaptation import LabviewAdaptation
from .potentiometer import Potentiometer
from .proportional_solenoid import ProportionalSolenoid
from .pump import Pump
from .rotary_actuator import RotaryActuator
from .spool import Spool

__all__ = [
    "Amplifier", "Component", "Cylinder", "DirectionalValve", "Fluid", "Hose", "LabviewAdaptation",
    "Parameter", "ParameterError", "Potentiometer", "ProportionalSolenoid", "Pump", "RotaryActuator", "Spool",
]
