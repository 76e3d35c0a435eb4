from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, col
from .base import CITE_CATALOG, Effect

LEAK_INT, LEAK_EXT = AP.declare(
    "leakage",
    col("LEAK_INT", "m^3/(s Pa)", "cross-port leakage coefficient"),
    col("LEAK_EXT", "m^3/(s Pa)", "external leakage coefficient of each chamber to tank"),
)


class Leakage(Effect):
    """Laminar leakage: across the piston/vanes (internal) and from each chamber to tank (external).

    Q_int = C_i (p_A - p_B) from A to B;  Q_ext,A = C_e (p_A - p_T), Q_ext,B = C_e (p_B - p_T).
    Speed under load drops by about C_i p_L / A; with the valve closed a loaded joint keeps drifting
    as oil leaks across the piston and to tank, and the chamber pressures redistribute. The
    harvester swing motor has both (Papadopoulos et al. 2003, Fig. 7).
    """

    name = "leakage"
    citation = "E. Papadopoulos et al., IEEE/ASME T-Mech 8(2), 2003, Sec. III-e and Fig. 7; " + CITE_CATALOG + " (§3.7)"
    PARAMETERS = (
        Parameter("internal", "m^3/(s Pa)", "cross-port leakage coefficient", 2e-12, 0.0, 3e-10),
        Parameter("external", "m^3/(s Pa)", "leakage coefficient of each chamber to tank", 0.0, 0.0, 1e-10),
    )
    HOOKS = {"leakage": "chamber_leakage"}
    CONFUSIONS = {"area_ratio": "holds at several loads, or chamber pressures"}

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, LEAK_INT] = params["internal"]
        lw.AP[a, LEAK_EXT] = params["external"]

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        ci = current["internal"] if current else 0.0
        ce = current["external"] if current else 0.0
        lo_i, lo_e = 1e-15, 1e-16
        if current:
            grid = [[max(ci, lo_i) * f, max(ce, lo_e) * f2] for f, f2 in ((0.3, 1.0), (3.0, 1.0), (1.0, 0.3), (1.0, 3.0), (3.0, 3.0))]
        else:
            grid = [[c, lo_e * 10] for c in (1e-13, 1e-12, 1e-11, 5e-11)] + [[lo_i * 10, c] for c in (1e-13, 1e-12, 1e-11)]
        return {"free": [("internal", lo_i, 3e-10, True, ci, "m^3/(s Pa)"), ("external", lo_e, 1e-10, True, ce, "m^3/(s Pa)")],
                "fixed": {"internal": max(ci, lo_i), "external": max(ce, lo_e)}, "grid": grid}


@njit(inline="always")
def chamber_leakage(pa, pb, p_t, a, AP):
    """Flows leaving chambers A and B by leakage (m^3/s) and their slopes d/dp_own."""
    c_int = AP[a, LEAK_INT]
    c_ext = AP[a, LEAK_EXT]
    q_int = c_int * (pa - pb)
    return q_int + c_ext * (pa - p_t), -q_int + c_ext * (pb - p_t), c_int + c_ext, c_int + c_ext
