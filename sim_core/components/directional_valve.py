"""4/3 proportional directional valve: four metering edges with the orifice law."""

import math

from numba import njit

from ..kernel.layout import AP, col
from .base import Component, Parameter, ParameterError

KV, OVERLAP, NULL_LEAK, POLY1, POLY2, POLY3, DP_TR, FLOW_EXP, DP_RATED = AP.declare(
    "valve",
    col("KV", "m^3/s/Pa^n", "valve flow coefficient per metering edge at full opening (n: FLOW_EXP)"),
    col("OVERLAP", "-", "spool overlap (stroke fraction)"),
    col("NULL_LEAK", "-", "null leakage opening of every edge (fraction of full opening)"),
    col("POLY1", "-", "opening characteristic a(s) = c1 s + c2 s^2 + c3 s^3"),
    col("POLY2", "-", "opening characteristic, c2"),
    col("POLY3", "-", "opening characteristic, c3"),
    col("DP_TR", "Pa", "laminar/turbulent transition pressure of the orifices"),
    col("FLOW_EXP", "-", "exponent n of the metering edges' flow law Q ~ dp^n (0.5: turbulent orifice)"),
    col("DP_RATED", "Pa", "pressure drop per edge at which the rated flow is given"),
)

CITATION_VALVE = (
    "H. E. Merritt, Hydraulic Control Systems, Wiley, 1967, ch. 3; E. Papadopoulos, B. Mu, R. Frenette, "
    "'On modeling, identification, and control of a heavy-duty electrohydraulic harvester manipulator', "
    "IEEE/ASME T-Mech 8(2), 2003, eqs. (1)-(2) and Fig. 5; A. Ellman, R. Piche, 'A two regime orifice "
    "flow formula for numerical simulation', J. Dyn. Sys. Meas. Control 121(4), 1999"
)


class DirectionalValve(Component):
    """Critically centred 4/3 spool valve (P->A, B->T for s > 0; P->B, A->T for s < 0).

    Each metering edge follows the orifice law with a laminar region near zero pressure drop:

        Q = K_v a(s) f(dp),   f(dp) = dp (dp^2 + dp_tr^2)^((n - 1) / 2)

    ``f`` is |dp|^n sign(dp) in the turbulent regime and dp dp_tr^(n - 1) (laminar, finite slope)
    for |dp| << dp_tr, so the pressure equations stay well conditioned when a chamber approaches the
    supply or tank pressure (Ellman & Piche 1999). ``K_v = Q_rated / dp_rated^n`` per edge. The
    exponent ``n`` (``flow_exponent``) is 0.5 for a sharp-edged orifice; a valve whose measured
    flow-vs-drop curve is flatter or steeper (spool slots with a long land, flow forces) is described
    by another ``n``; ``rated_flow`` keeps its meaning, the flow at ``rated_pressure_drop``.

    The opening characteristic maps the metering spool position ``s`` (stroke fraction, overlap
    removed) to the relative orifice area:

        s' = max(|s| - o, 0) / (1 - o),   a(s') = c1 s' + c2 s'^2 + c3 s'^3,   c1 + c2 + c3 = 1

    A linear characteristic (c = 1, 0, 0) suits a proportional valve with rectangular slots; the
    harvester valves use the third-order fit of the valve coefficient against voltage of
    Papadopoulos et al. (Fig. 5). Every edge additionally leaks ``null_leakage`` of full opening
    (underlap); 0 gives a zero-leakage critical centre.
    """

    section = "valve"
    citation = CITATION_VALVE
    PARAMETERS = (
        Parameter("rated_flow", "m^3/s", "flow through one metering edge at full opening and the rated pressure drop", None, 1e-7, 0.1),
        Parameter("rated_pressure_drop", "Pa", "pressure drop per metering edge at which rated_flow is given", 3.5e6, 1e4, 1e8),
        Parameter("overlap", "-", "spool overlap as a fraction of the metering stroke (geometric deadband)", 0.0, 0.0, 0.9),
        Parameter("null_leakage", "-", "leakage opening of every edge at centre, fraction of full opening", 0.0, 0.0, 0.1),
        Parameter("transition_pressure", "Pa", "pressure drop of the laminar/turbulent transition", 1.0e5, 1e2, 5e6),
        Parameter("characteristic", "-", "opening polynomial coefficients [c1, c2, c3], sum 1", (1.0, 0.0, 0.0), kind="vec", length=3),
        Parameter("flow_exponent", "-", "exponent n of the edges' flow law Q ~ dp^n (0.5: turbulent orifice)", 0.5, 0.3, 1.0),
    )

    def __init__(self, values=None, where=""):
        super().__init__(values, where)
        c = self.values["characteristic"]
        if abs(sum(c) - 1.0) > 1e-6:
            raise ParameterError(f"{self.where}.characteristic: coefficients must sum to 1 (a(1) = full opening), got {list(c)}")
        # a(s') must increase on [0, 1]: check the derivative on a grid
        for k in range(101):
            s = k / 100.0
            if c[0] + 2.0 * c[1] * s + 3.0 * c[2] * s * s < -1e-12:
                raise ParameterError(f"{self.where}.characteristic: opening must not decrease with spool travel")

    @property
    def flow_coefficient(self) -> float:
        """K_v per edge at full opening (m^3/s/Pa^n, n = flow_exponent)."""
        n, dp = self.values["flow_exponent"], self.values["rated_pressure_drop"]
        return self.values["rated_flow"] / (math.sqrt(dp) if n == 0.5 else dp ** n)

    def full_opening_flow(self, dp: float) -> float:
        """Flow (m^3/s) through one fully open edge at the pressure drop ``dp`` (Pa), by the valve's
        law Q ~ dp^n from its rated point (the turbulent, high-drop side of the law)."""
        n, r = self.values["flow_exponent"], dp / self.values["rated_pressure_drop"]
        return self.values["rated_flow"] * (math.sqrt(r) if n == 0.5 else r ** n)

    def lower(self, lw, a, spec, js):
        AP_ = lw.AP
        AP_[a, KV] = self.flow_coefficient
        AP_[a, OVERLAP] = self["overlap"]
        AP_[a, NULL_LEAK] = self["null_leakage"]
        AP_[a, POLY1], AP_[a, POLY2], AP_[a, POLY3] = self["characteristic"]
        AP_[a, DP_TR] = self["transition_pressure"]
        AP_[a, FLOW_EXP] = self["flow_exponent"]
        AP_[a, DP_RATED] = self["rated_pressure_drop"]


@njit(inline="always")
def orifice(dp, tr):
    """Regularised orifice function f(dp) (sqrt(Pa)) with its slope df/d(dp): the flow law with
    exponent 1/2."""
    s = dp * dp + tr * tr
    r = math.sqrt(math.sqrt(s))        # s^(1/4): sqrt(sqrt()) is ~3x faster than pow(s, 0.25)
    f = dp / r
    slope = (0.5 * dp * dp + tr * tr) / (s * r)
    return f, slope


@njit(inline="always")
def orifice_n(dp, tr, n):
    """f(dp) = dp (dp^2 + dp_tr^2)^((n - 1) / 2) (Pa^n) and its slope, for a flow exponent ``n``
    (n = 0.5 takes :func:`orifice`, bit for bit)."""
    if n == 0.5:
        return orifice(dp, tr)
    s = dp * dp + tr * tr
    r = s ** (0.5 * (1.0 - n))         # (dp^2 + tr^2)^((1 - n) / 2)
    f = dp / r
    slope = (n * dp * dp + tr * tr) / (s * r)
    return f, slope


@njit(inline="always")
def opening(s, overlap, c1, c2, c3):
    """Relative orifice area of the edges opened by a positive spool travel ``s`` (s >= 0)."""
    if s <= overlap:
        return 0.0
    x = (s - overlap) / (1.0 - overlap)
    if x > 1.0:  # past full opening (stroke_limit > 1): continue with the end slope
        return 1.0 + (x - 1.0) * (c1 + 2.0 * c2 + 3.0 * c3)
    return x * (c1 + x * (c2 + x * c3))


@njit(inline="always")
def edge_conductances(a, s, kvn, AP):
    """(g_PA = g_BT, g_PB = g_AT): conductances of the edges a spool travel ``s`` opens; ``kvn`` is
    the flow coefficient of the negative-travel edges (K_v unless an effect makes them differ)."""
    sp = s if s > 0.0 else 0.0
    sn = -s if s < 0.0 else 0.0
    ov = AP[a, OVERLAP]
    c1 = AP[a, POLY1]
    c2 = AP[a, POLY2]
    c3 = AP[a, POLY3]
    leak0 = AP[a, NULL_LEAK]
    g_pa = AP[a, KV] * (opening(sp, ov, c1, c2, c3) + leak0)    # P->A and B->T
    g_pb = kvn * (opening(sn, ov, c1, c2, c3) + leak0)          # P->B and A->T
    return g_pa, g_pb


@njit(inline="always")
def edge_flows(a, g_pa, g_pb, p_s, p_t, ua, ub, AP):
    """Flows of the four metering edges for port pressures ``ua``, ``ub`` and their slopes with
    respect to the port pressure (P->A, A->T, P->B, B->T). Closed edges pass nothing: a spool
    travelling one way leaves the other pair shut (unless the valve leaks at null)."""
    tr = AP[a, DP_TR]
    n = AP[a, FLOW_EXP]
    q_pa = q_bt = dq_pa = dq_bt = 0.0
    q_pb = q_at = dq_pb = dq_at = 0.0
    if g_pa != 0.0:
        f_pa, d_pa = orifice_n(p_s - ua, tr, n)
        f_bt, d_bt = orifice_n(ub - p_t, tr, n)
        q_pa = g_pa * f_pa
        q_bt = g_pa * f_bt
        dq_pa = -g_pa * d_pa
        dq_bt = g_pa * d_bt
    if g_pb != 0.0:
        f_at, d_at = orifice_n(ua - p_t, tr, n)
        f_pb, d_pb = orifice_n(p_s - ub, tr, n)
        q_at = g_pb * f_at
        q_pb = g_pb * f_pb
        dq_at = g_pb * d_at
        dq_pb = -g_pb * d_pb
    return q_pa, q_at, q_pb, q_bt, dq_pa, dq_at, dq_pb, dq_bt


@njit(inline="always")
def valve_flows_only(a, g_pa, g_pb, p_s, p_t, ua, ub, AP):
    """The four edge flows without slopes (reference solver)."""
    tr = AP[a, DP_TR]
    n = AP[a, FLOW_EXP]
    return (g_pa * orifice_n(p_s - ua, tr, n)[0], g_pb * orifice_n(ua - p_t, tr, n)[0],
            g_pb * orifice_n(p_s - ub, tr, n)[0], g_pa * orifice_n(ub - p_t, tr, n)[0])
