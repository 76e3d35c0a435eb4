from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


class ValveAsymmetry(Effect):
    """Direction-dependent valve gain: the negative-travel edges pass ratio x the positive flow.

    K_v(s < 0) = r K_v(s > 0) (unequal solenoids or metering notches). Negative commands move the
    joint r times as fast as the nominal model predicts (at equal load), positive ones unchanged.
    """

    name = "valve_asymmetry"
    citation = CITE_CATALOG + " (§3.5)"
    PARAMETERS = (Parameter("ratio", "-", "flow gain of negative over positive spool travel", 0.85, 0.3, 2.0),)

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_E_ASYM] = 1.0
        lw.AP[a, L.AP_ASYM_RATIO] = params["ratio"]
