from numba import njit

from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


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

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_E_DEADBAND] = 1.0
        lw.AP[a, L.AP_DB_WIDTH] = params["width"]


@njit(cache=True, inline="always")
def dead_zone(u, w):
    if u > w:
        return u - w
    if u < -w:
        return u + w
    return 0.0
