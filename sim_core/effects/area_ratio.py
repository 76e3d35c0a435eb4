from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


class AreaRatio(Effect):
    """Cylinder annulus-to-piston area ratio different from the nominal rod diameter.

    A_B = alpha A_A. For a given valve opening the retraction speed changes relative to extension
    (roughly with 1/alpha at low load), and the chamber pressures redistribute
    (p_A A_A - p_B A_B = F): a smaller ratio raises the rod-side pressure in a hold.
    """

    name = "area_ratio"
    actuators = ("cylinder",)
    citation = CITE_CATALOG + " (§3.6)"
    PARAMETERS = (Parameter("ratio", "-", "rod-side over cap-side area A_B / A_A", 0.5, 0.1, 0.99),)

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_AREA_B] = params["ratio"] * lw.AP[a, L.AP_AREA_A]
