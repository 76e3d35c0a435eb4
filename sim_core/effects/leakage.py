from ..components.base import Parameter
from ..kernel import layout as L
from .base import CITE_CATALOG, Effect


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

    @classmethod
    def lower(cls, params, lw, a):
        lw.AP[a, L.AP_E_LEAK] = 1.0
        lw.AP[a, L.AP_LEAK_INT] = params["internal"]
        lw.AP[a, L.AP_LEAK_EXT] = params["external"]
