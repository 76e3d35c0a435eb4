from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, col
from .base import CITE_JELALI, Effect, clip_grid

VO_OFFSET = AP.declare("valve_offset", col("VO_OFFSET", "V", "valve null offset (command equivalent)"))

SPAN = 0.15      # the candidate's search bound: this share of the joint's largest command (V)


class ValveOffset(Effect):
    """Valve null offset: the spool's centre, with its amplifier, sits off the commanded zero.

    u_e = u + d (d in volts of command). At zero command the valve passes the flow of a d-volt
    command, so the joint creeps one way, whatever the load, at the speed a command d would give; a
    command of -d holds it still. Under closed-loop control the controller holds -d at rest, and a
    model without the offset, driven by that recorded command, drifts the other way. Servo and
    proportional valves leave the factory nulled to within a few percent of rated current, and the
    null drifts with temperature, supply pressure and wear (null shift); amplifiers add their own bias.
    """

    name = "valve_offset"
    citation = (CITE_JELALI + " (servo-valve null shift); H. E. Merritt, Hydraulic Control Systems, Wiley, "
                "1967 (valve null shift)")
    PARAMETERS = (Parameter("offset", "V", "command-equivalent shift of the valve's null (positive: flow "
                                           "as for a positive command)", 0.2, -5.0, 5.0),)
    HOOKS = {"command": "valve_offset_command"}
    ORDER = 1.5          # after the delay and the solenoid's hysteresis, before the spool overlap's deadband
    CONFUSIONS = {
        "leakage": "holding at several poses with the load pulling both ways (a leak creeps with the load, an offset "
                   "one way whatever the load)",
        "hysteresis": "command reversals from both sides (hysteresis creeps in the last direction, an offset always in one)",
        "valve_asymmetry": "small commands of both signs (an offset shifts the null, an asymmetry scales one side)",
    }

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, VO_OFFSET] = params["offset"]

    @classmethod
    def reference_command(cls, u, a, AP_, XS_, memory):
        return u + AP_[a, VO_OFFSET]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        lo_u, hi_u = spec.joint(joint).command_range
        bound = SPAN * max(abs(lo_u), abs(hi_u))
        if current is not None:          # a spec's own offset is refitted around its value, whatever its size
            bound = max(bound, 1.5 * abs(current["offset"]))
        base = [0.02, 0.05, 0.1, 0.3, 0.7]
        if current is None:
            grid = [s * v * bound for v in base for s in (-1.0, 1.0)]
        else:
            d0 = current["offset"]
            grid = [d0 + s * v * bound for v in base[:3] for s in (-1.0, 1.0)]
        null = current["offset"] if current else 0.0
        return {"free": [("offset", -bound, bound, False, null, "V")],
                "grid": [[v] for v in clip_grid(grid, -bound, bound)]}


@njit(inline="always")
def valve_offset_command(u, a, t, h, AP, XS, XG, HT, HU):
    return u + AP[a, VO_OFFSET]
