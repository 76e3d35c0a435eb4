"""The two oil chambers of every actuator: pressure states, port reliefs, fault leaks, cavitation.

Every actuator kind (cylinder, rotary actuator or motor) has a chamber A (positive motion fills
it) and a chamber B. What differs between kinds, the volumes and the displaced flows, comes from
the actuator's own file; the chambers hold what they share:

    C_A dp_A/dt = Q_A - Q_disp,A - Q_leak,A,     C_B dp_B/dt = Q_B - Q_disp,B - Q_leak,B
    Q_leak  = cross-port and external leakage (``leakage`` effect) + fault leaks to tank
              + port relief K_r max(p - p_relief, 0)
    p >= p_cavitation (vapour pressure, gauge)

The port reliefs pass the valve's rated flow 0.5 MPa above cracking. This is not a section of the
robot spec: its parameters come from the actuator's ``port_relief_pressure``, the valve's
``rated_flow`` and the fault injection (``leak``).
"""

from numba import njit

from ..kernel.layout import AP, XS, col

P_A, P_B, Q_A, Q_B = XS.declare(
    "chambers",
    col("P_A", "Pa", "chamber A pressure", ode=True, atol=1e-2),
    col("P_B", "Pa", "chamber B pressure", ode=True, atol=1e-2),
    col("Q_A", "m^3/s", "last valve flow into line A"),
    col("Q_B", "m^3/s", "last valve flow into line B"),
)
AREA_A, AREA_B, VDEAD_A, VDEAD_B, VISC, RELIEF_P, RELIEF_K, F_LEAK_A, F_LEAK_B = AP.declare(
    "chambers",
    col("AREA_A", "m^2 or m^3/rad", "cylinder: piston area; rotary: gear ratio * displacement"),
    col("AREA_B", "m^2 or m^3/rad", "cylinder: annulus area; rotary: same as AREA_A"),
    col("VDEAD_A", "m^3", "chamber A dead volume incl. valve/manifold passages"),
    col("VDEAD_B", "m^3", "chamber B dead volume"),
    col("VISC", "N s/m or N m s/rad", "viscous seal friction: at the rod (cylinder) or at the joint (rotary)"),
    col("RELIEF_P", "Pa", "port relief cracking pressure (0: none)"),
    col("RELIEF_K", "m^3/s/Pa", "port relief conductance above cracking"),
    col("F_LEAK_A", "m^3/s/Pa", "fault: laminar leak of chamber A to tank"),
    col("F_LEAK_B", "m^3/s/Pa", "fault: laminar leak of chamber B to tank"),
)

FAULTS = ("leak",)


def lower_relief(lw, a, relief_pressure: float, rated_flow: float) -> None:
    lw.AP[a, RELIEF_P] = relief_pressure
    lw.AP[a, RELIEF_K] = rated_flow / 5e5


def lower_fault(lw, a, kind, mode):
    c = float(mode.get("coefficient", 1e-11))
    if mode.get("chamber", "a") in ("a", "both"):
        lw.AP[a, F_LEAK_A] = c
    if mode.get("chamber", "a") in ("b", "both"):
        lw.AP[a, F_LEAK_B] = c


@njit(inline="always")
def chamber_outflows(a, pa, pb, p_t, AP):
    """Flows leaving chambers A and B besides the actuator's displacement (fault leaks, port reliefs)
    and their slopes d/dp_own (m^3/s, m^3/s/Pa)."""
    lk_a = AP[a, F_LEAK_A] * (pa - p_t)
    lk_b = AP[a, F_LEAK_B] * (pb - p_t)
    dlk_a = AP[a, F_LEAK_A]
    dlk_b = AP[a, F_LEAK_B]
    p_relief = AP[a, RELIEF_P]
    if p_relief > 0.0:
        k_relief = AP[a, RELIEF_K]
        if pa > p_relief:
            lk_a += k_relief * (pa - p_relief)
            dlk_a += k_relief
        if pb > p_relief:
            lk_b += k_relief * (pb - p_relief)
            dlk_b += k_relief
    return lk_a, lk_b, dlk_a, dlk_b


@njit(inline="always")
def floor(p, p_min):
    """Cavitation floor: a chamber cannot fall below vapour pressure."""
    return p_min if p < p_min else p
