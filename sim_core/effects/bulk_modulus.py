from numba import njit

from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


class BulkModulus(Effect):
    """Entrained air and soft hoses: lower, pressure-dependent effective bulk modulus.

    beta_e(p) = s beta / (1 + p_air / (p + p_atm)) in every chamber and hose. The hydraulic spring
    softens, most at low pressure: the hydraulic natural frequency drops, pressures build up more
    slowly after a command, and the joint overshoots and rings more.
    """

    name = "bulk_modulus"
    scope = "global"
    citation = "H. E. Merritt, Hydraulic Control Systems, 1967, §2.5; " + CITE_CATALOG + " (§3.12)"
    PARAMETERS = (
        Parameter("scale", "-", "multiplier on the bulk modulus at high pressure", 0.5, 0.05, 2.0),
        Parameter("air_pressure", "Pa", "pressure scale of the entrained-air softening", 5e5, 0.0, 5e6),
    )

    @classmethod
    def lower(cls, params, lw, a):
        lw.GP[L.GP_E_BULK] = 1.0
        lw.GP[L.GP_BULK_SCALE] = params["scale"]
        lw.GP[L.GP_BULK_PAIR] = params["air_pressure"]


@njit(cache=True, inline="always")
def bulk_factor(p, on, scale, p_air, p_atm):
    """Multiplier on the nominal bulk modulus at gauge pressure ``p``."""
    if on == 0.0:
        return 1.0
    pa = p + p_atm
    if pa < 1e3:
        pa = 1e3
    return scale / (1.0 + p_air / pa)
