from ..components.base import Parameter
from ..kernel import layout as L
from ..components.hose import CITATION_HOSE
from .base import Effect


class LineDynamics(Effect):
    """Hose line dynamics: T-type lumped capacitance, inertance and resistance per line.

    See the ``hose`` component for the equations. The hose compliance in series with the chamber
    softens the hydraulic spring, so a step excites a lightly damped line-plus-load oscillation,
    visible first in the pressures (about 3 Hz on the harvester boom, Papadopoulos et al. 2003,
    Figs. 9 and 13). The scale multiplies the hose's effective bulk modulus.
    """

    name = "line_dynamics"
    citation = CITATION_HOSE
    PARAMETERS = (Parameter("bulk_modulus_scale", "-", "multiplier on the hose effective bulk modulus", 1.0, 0.05, 3.0),)

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_E_LINE] = 1.0
        lw.AP[a, L.AP_HOSE_BETA] *= params["bulk_modulus_scale"]
