from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, col
from .base import CITE_CATALOG, Effect, clip_grid

ASYM_RATIO = AP.declare("valve_asymmetry", col("ASYM_RATIO", "-", "K_v(negative) / K_v(positive)"))


class ValveAsymmetry(Effect):
    """Direction-dependent valve gain: the negative-travel edges pass ratio x the positive flow.

    K_v(s < 0) = r K_v(s > 0) (unequal solenoids or metering notches). Negative commands move the
    joint r times as fast as the nominal model predicts (at equal load), positive ones unchanged.
    """

    name = "valve_asymmetry"
    citation = CITE_CATALOG + " (§3.5)"
    PARAMETERS = (Parameter("ratio", "-", "flow gain of negative over positive spool travel", 0.85, 0.3, 2.0),)
    HOOKS = {"negative_gain": "negative_edge_gain"}
    CONFUSIONS = {
        "area_ratio": "chamber pressures (the area ratio changes the p_A/p_B intensification, a valve asymmetry does not)",
        "payload": "records at other poses (a payload scales with cos of the link angle) or chamber pressures",
        "flow_saturation": "large and small commands in both directions (saturation depends on |u|)",
        "leakage": "holds at several loads (leakage drifts with the load pressure, an asymmetry only moves with the command)",
    }

    @classmethod
    def lower_neutral(cls, lw, a):
        lw.AP[a, ASYM_RATIO] = 1.0

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, ASYM_RATIO] = params["ratio"]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        r0 = current["ratio"] if current else 1.0
        grid = [r0 * f for f in (0.6, 0.8, 1.25, 1.6)] + ([guess["ratio"] * r0] if "ratio" in guess else [])
        return {"free": [("ratio", 0.3, 2.0, True, r0, "")], "grid": [[v] for v in clip_grid(grid, 0.3, 2.0)]}

    @classmethod
    def signature_guess(cls, sig, context):
        r = sig.get("asymmetry_ratio")
        return {"ratio": float(r)} if r is not None and r > 0 else None


@njit(inline="always")
def negative_edge_gain(kv, a, AP):
    return kv * AP[a, ASYM_RATIO]
