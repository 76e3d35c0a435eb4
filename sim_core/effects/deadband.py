from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, col
from .base import CITE_CATALOG, Effect, clip_grid

DB_WIDTH = AP.declare("deadband", col("DB_WIDTH", "V", "deadband width"))


class Deadband(Effect):
    """Valve deadband: no flow until the command exceeds the width (spool overlap, in volts).

    u_e = sign(u) * max(|u| - w, 0). Below |u| = w the joint does not move at all; above it the
    valve opens as if commanded |u| - w, so large-signal speed is slightly reduced. The harvester
    valves have 0-1.2 V of deadband (Papadopoulos et al. 2003, Fig. 5); proportional valves are
    often 10-20 % overlapped unless the amplifier compensates.
    """

    name = "deadband"
    citation = "E. Papadopoulos et al., IEEE/ASME T-Mech 8(2), 2003, Fig. 5; " + CITE_CATALOG + " (§3.1)"
    PARAMETERS = (Parameter("width", "V", "command voltage below which the valve stays closed", 1.0, 0.0, 5.0),)
    HOOKS = {"command": "deadband_command"}
    ORDER = 2
    CONFUSIONS = {
        "coulomb_friction": "chamber pressures (friction loads the pressure, a deadband stops the flow)",
        "hysteresis": "small command steps from both directions (hysteresis has memory)",
    }

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, DB_WIDTH] = params["width"]

    @classmethod
    def reference_command(cls, u, a, AP_, XS_, memory):
        return dead_zone(u, AP_[a, DB_WIDTH])

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        if current is None:
            grid = [0.1, 0.25, 0.5, 0.8, 1.2, 1.8, 2.6, 3.6]
        else:
            w0 = current["width"]
            grid = [w0 * f for f in (0.5, 0.75, 1.25, 1.6, 2.2)]
        if "width" in guess:
            grid.append(guess["width"])
        null = current["width"] if current else 0.0
        return {"free": [("width", 0.0, 4.5, False, null, "V")], "grid": [[v] for v in clip_grid(grid, 0.0, 4.5)]}

    @classmethod
    def signature_guess(cls, sig, context):
        u0 = sig.get("deadband_u0")
        if u0 is not None and u0 > 0:
            return {"width": float(context.get("model_deadband", 0.0) + u0)}
        return None


@njit(inline="always")
def dead_zone(u, w):
    if u > w:
        return u - w
    if u < -w:
        return u + w
    return 0.0


@njit(inline="always")
def deadband_command(u, a, t, h, AP, XS, XG, HT, HU):
    return dead_zone(u, AP[a, DB_WIDTH])
