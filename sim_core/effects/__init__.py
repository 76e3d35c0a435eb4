"""The effect bank: every physical effect is a switchable submodel with named parameters.

Effects are off unless a robot's spec, a parameter file or a command switches them on. The
catalog (``hydrohil effects --json``) is generated from these classes. Adding an effect: its file
(see ``base.Effect``) and one entry below; the kernel, the reference solver, the energy check and the
diagnosis pick it up from there.
"""

from .area_ratio import AreaRatio
from .backlash import Backlash
from .base import Effect, EffectInstance
from .bulk_modulus import BulkModulus
from .coulomb_friction import CoulombFriction
from .deadband import Deadband
from .delay import Delay
from .flow_saturation import FlowSaturation
from .hysteresis import Hysteresis
from .joint_compliance import JointCompliance
from .leakage import Leakage
from .line_dynamics import LineDynamics
from .payload import Payload
from .pump_limit import PumpLimit
from .sensor_gain import SensorGain
from .sensor_offset import SensorOffset
from .spool_lag import SpoolLag
from .stribeck_friction import StribeckFriction
from .valve_asymmetry import ValveAsymmetry
from .valve_offset import ValveOffset

EFFECTS: dict[str, type[Effect]] = {
    e.name: e
    for e in (
        Deadband, ValveAsymmetry, SpoolLag, Delay, Leakage, CoulombFriction, Backlash, AreaRatio,
        FlowSaturation, LineDynamics, JointCompliance, Payload, SensorOffset, SensorGain, Hysteresis,
        BulkModulus, StribeckFriction, ValveOffset, PumpLimit,
    )
}


def get_effect(name: str) -> type[Effect]:
    try:
        return EFFECTS[name]
    except KeyError:
        raise KeyError(f"unknown effect {name!r}; known effects: {', '.join(EFFECTS)}") from None


def diagnosable() -> dict[str, type[Effect]]:
    """The effects the diagnosis can fit (those that give ``Effect.candidate`` hints); the others
    (stribeck_friction) are simulation-only: records made with them test out-of-bank behaviour."""
    return {n: e for n, e in EFFECTS.items() if e.candidate.__func__ is not Effect.candidate.__func__}


def catalog() -> list[dict]:
    return [e.describe() for e in EFFECTS.values()]


__all__ = ["EFFECTS", "Effect", "EffectInstance", "catalog", "diagnosable", "get_effect"]
