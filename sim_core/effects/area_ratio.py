from ..components.base import Parameter
from ..components.chambers import AREA_A, AREA_B
from .base import CITE_CATALOG, Effect, clip_grid


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
    switch = False          # changes a parameter of the cylinder at lowering; no equations of its own
    CONFUSIONS = {"payload": "chamber pressures in holds at two poses"}

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, AREA_B] = params["ratio"] * lw.AP[a, AREA_A]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        r0 = current["ratio"] if current else scales["area_ratio"]
        grid = [r0 * f for f in (0.6, 0.8, 0.9, 1.1, 1.25)]
        return {"free": [("ratio", 0.1, 0.99, False, r0, "")], "fixed": {"ratio": r0},
                "grid": [[v] for v in clip_grid(grid, 0.1, 0.99)]}
