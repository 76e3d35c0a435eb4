from numba import njit

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


@njit(cache=True, inline="always")
def chamber_leakage(pa, pb, p_t, c_int, c_ext, c_fault_a, c_fault_b, p_relief, k_relief):
    """Flows leaving chambers A and B (m^3/s) and their slopes d/dp_own: cross-port leakage A->B,
    external leakage and fault leaks to tank, and port reliefs above ``p_relief`` (0 = none)."""
    q_int = c_int * (pa - pb)
    lk_a = q_int + (c_ext + c_fault_a) * (pa - p_t)
    lk_b = -q_int + (c_ext + c_fault_b) * (pb - p_t)
    dlk_a = c_int + c_ext + c_fault_a
    dlk_b = c_int + c_ext + c_fault_b
    if p_relief > 0.0:
        if pa > p_relief:
            lk_a += k_relief * (pa - p_relief)
            dlk_a += k_relief
        if pb > p_relief:
            lk_b += k_relief * (pb - p_relief)
            dlk_b += k_relief
    return lk_a, lk_b, dlk_a, dlk_b
