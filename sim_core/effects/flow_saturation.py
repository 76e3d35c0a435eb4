import math

from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, col
from .base import CITE_CATALOG, Effect, clip_grid

FLOWSAT_Q = AP.declare("flow_saturation", col("FLOWSAT_Q", "m^3/s", "largest flow of a supply edge"))


class FlowSaturation(Effect):
    """Flow limit of the valve section (pump share, amplifier current limit, valve size).

    Q_P->A, Q_P->B <= Q_max. The joint speed stops growing with the command once the valve would pass
    more than Q_max: large commands all give about the same speed (Q_max / A), small ones are
    unaffected.
    """

    name = "flow_saturation"
    citation = CITE_CATALOG + " (§3.11)"
    PARAMETERS = (Parameter("max_flow", "m^3/s", "largest flow the supply edge passes", 5e-5, 1e-7, 0.05),)
    HOOKS = {"edge_limit": "limit_supply_edges"}
    CONFUSIONS = {"area_ratio": "large commands in both directions"}

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, FLOWSAT_Q] = params["max_flow"]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        q = scales["q_full"]
        lo, hi = 0.02 * q, 2.0 * q
        grid = [q * f for f in (0.08, 0.15, 0.25, 0.4, 0.6, 0.85)]
        null = current["max_flow"] if current else math.inf
        return {"free": [("max_flow", lo, hi, True, null, "m^3/s")], "fixed": {"max_flow": hi},
                "grid": [[v] for v in clip_grid(grid, lo, hi)]}


@njit(inline="always")
def limit_supply_edges(q_pa, dq_pa, q_pb, dq_pb, a, AP):
    """The supply edges (P->A, P->B) clipped at Q_max; a clipped flow no longer depends on pressure."""
    qmax = AP[a, FLOWSAT_Q]
    if abs(q_pa) > qmax:
        q_pa = qmax if q_pa > 0.0 else -qmax
        dq_pa = 0.0
    if abs(q_pb) > qmax:
        q_pb = qmax if q_pb > 0.0 else -qmax
        dq_pb = 0.0
    return q_pa, dq_pa, q_pb, dq_pb
