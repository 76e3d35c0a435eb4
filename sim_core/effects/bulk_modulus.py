import math

from numba import njit

from ..components.base import Parameter
from ..components.fluid import ATM
from ..kernel.layout import GP, col
from .base import Effect

BULK_SCALE, BULK_PAIR = GP.declare(
    "bulk_modulus",
    col("BULK_SCALE", "-", "multiplier on the bulk modulus at high pressure"),
    col("BULK_PAIR", "Pa", "entrained-air pressure scale"),
)


class BulkModulus(Effect):
    """Entrained air and soft hoses: lower, pressure-dependent effective bulk modulus.

    beta_e(p) = s beta / (1 + p_air / (p + p_atm)) in every chamber and hose. The hydraulic spring
    softens, most at low pressure: the hydraulic natural frequency drops, pressures build up more
    slowly after a command, and the joint overshoots and rings more. Oil compressed to p stores
    V/beta int_0^p p'/f(p') dp' = V/(s beta) [p^2/2 + p_air (p - p_atm ln((p + p_atm)/p_atm))].
    """

    name = "bulk_modulus"
    scope = "global"
    citation = "H. E. Merritt, Hydraulic Control Systems, 1967, §2.5; HydroHIL research note 'discrepancy catalog' (§3.12)"
    PARAMETERS = (
        Parameter("scale", "-", "multiplier on the bulk modulus at high pressure", 0.5, 0.05, 2.0),
        Parameter("air_pressure", "Pa", "pressure scale of the entrained-air softening", 5e5, 0.0, 5e6),
    )
    HOOKS = {"bulk": "air_softened", "compression_energy": "air_compression_energy"}

    @classmethod
    def lower_neutral(cls, lw, a):
        lw.GP[BULK_SCALE] = 1.0

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.GP[BULK_SCALE] = params["scale"]
        lw.GP[BULK_PAIR] = params["air_pressure"]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        s0 = current["scale"] if current else 1.0
        a0 = current["air_pressure"] if current else 5e5
        return {"free": [("scale", 0.05, 2.0, True, s0, ""), ("air_pressure", 1e3, 5e6, True, a0 if current else 0.0, "Pa")],
                "grid": [[s * s0, a0] for s in (0.15, 0.3, 0.5, 0.75)] + [[s0, a] for a in (5e4, 2e6)]}


@njit(inline="always")
def air_softened(p, GP):
    """Multiplier on the nominal bulk modulus at gauge pressure ``p``."""
    pa = p + GP[ATM]
    if pa < 1e3:
        pa = 1e3
    return GP[BULK_SCALE] / (1.0 + GP[BULK_PAIR] / pa)


@njit(inline="always")
def air_compression_energy(p, GP):
    """G(p) = int_0^p p' / f(p') dp' (Pa^2) for f = s / (1 + p_air / (p + p_atm))."""
    pa = GP[ATM]
    return (0.5 * p * p + GP[BULK_PAIR] * (p - pa * math.log((p + pa) / pa))) / GP[BULK_SCALE]
