from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


class FlowSaturation(Effect):
    """Flow limit of the valve section (pump share, amplifier current limit, valve size).

    Q_P->A, Q_P->B <= Q_max. The joint speed stops growing with the command once the valve would pass
    more than Q_max: large commands all give about the same speed (Q_max / A), small ones are
    unaffected.
    """

    name = "flow_saturation"
    citation = CITE_CATALOG + " (§3.11)"
    PARAMETERS = (Parameter("max_flow", "m^3/s", "largest flow the supply edge passes", 5e-5, 1e-7, 0.05),)

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_E_FLOWSAT] = 1.0
        lw.AP[a, L.AP_FLOWSAT_Q] = params["max_flow"]
