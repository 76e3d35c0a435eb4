from ..components.base import Parameter
from ..components.pump import PUMP_QMAX
from .base import CITE_CATALOG, Effect, clip_grid


class PumpLimit(Effect):
    """A pump that gives less flow than the valves ask: the supply pressure falls while they draw more.

    The spec's pump (``supply.max_flow``, 0 = an ideal pressure source) becomes a flow source of at
    most Q_max feeding the supply line's oil (``supply.line_volume`` over the bulk modulus):
    C_s dp_s/dt = Q_pump - sum Q_valves - Q_relief. A small power unit, or one shared with other
    machines. Once a large command asks for more than Q_max, the supply pressure sags until the
    valve passes Q_max: the joint's speed stops growing with the command (Q_max / A), after a
    short surge from the line's stored oil as the valve opens, and the supply recovers over the
    next fraction of a second when it closes. With several joints, each slows while another moves.
    """

    name = "pump_limit"
    scope = "global"
    citation = CITE_CATALOG + " (§3.11); N. D. Manring, Hydraulic Control Systems, Wiley, 2005, ch. 6"
    PARAMETERS = (Parameter("max_flow", "m^3/s", "the most flow the pump delivers", 1e-4, 1e-7, 0.1),)
    switch = False          # sets the pump's flow limit at lowering; the supply node's equations are the pump's
    CONFUSIONS = {"flow_saturation": "a surge from the supply line's oil as the valve opens (and, with "
                                     "several joints, each slowing while another moves); the supply pressure"}

    @classmethod
    def lower(cls, params, lw, a):
        lw.GP[PUMP_QMAX] = params["max_flow"]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        ps = spec.supply["pressure"]
        flows = [js.components["valve"].full_opening_flow(ps) for js in spec.joints if "valve" in js.components]
        if not flows:
            return None
        q = max(flows)
        lo, hi = 0.02 * q, 2.0 * sum(flows)
        grid = [q * f for f in (0.08, 0.15, 0.25, 0.4, 0.6, 0.85)]
        spec_limit = spec.supply["max_flow"]
        null = current["max_flow"] if current else (spec_limit if spec_limit > 0 else hi)
        return {"free": [("max_flow", lo, hi, True, null, "m^3/s")], "fixed": {"max_flow": min(max(null, lo), hi)},
                "grid": [[v] for v in clip_grid(grid, lo, hi)]}
