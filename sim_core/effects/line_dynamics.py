from numba import njit

from ..components.base import Parameter
from ..components.fluid import P_MIN
from ..components.hose import CITATION_HOSE, HOSE_BETA, HOSE_I, HOSE_RLAM, HOSE_RTURB, HOSE_TURB, HOSE_VOL
from ..kernel.layout import XG_E_HOSE, XS, col
from .base import Effect, clip_grid

PH_A, PH_B, QH_A, QH_B = XS.declare(
    "line_dynamics",
    col("PH_A", "Pa", "hose valve-end node pressure, line A (the chamber's when the effect is off)", ode=True, atol=1e-2),
    col("PH_B", "Pa", "hose valve-end node pressure, line B", ode=True, atol=1e-2),
    col("QH_A", "m^3/s", "hose flow into chamber A (the valve's when the effect is off)", ode=True, atol=1e-12),
    col("QH_B", "m^3/s", "hose flow into chamber B", ode=True, atol=1e-12),
)


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
    HOOKS = {
        "port_pressures": "hose_node_pressures", "pressures": "t_line_pressures",
        "after_pressures": "store_line_nodes", "after_pressures_off": "follow_chambers",
        "reference_pressures": "t_line_derivatives",
    }
    CONFUSIONS = {"bulk_modulus": "pressures at the valve and at the chamber"}

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, HOSE_BETA] *= params["bulk_modulus_scale"]

    @classmethod
    def reset(cls, ctx, a, q_dof, tau, on):
        from ..components.chambers import P_A, P_B

        ctx.XS[a, PH_A] = ctx.XS[a, P_A]
        ctx.XS[a, PH_B] = ctx.XS[a, P_B]

    @classmethod
    def stored_energy(cls, ctx, a, out):
        from ..components.chambers import P_A, P_B

        AP_, XS_ = ctx.AP, ctx.XS
        if AP_[a, cls.switch_column] == 0.0:
            return False
        va, vb = ctx.chamber_volumes(a)
        beta, G = ctx.bulk_functions()
        pa, pb = XS_[a, P_A], XS_[a, P_B]
        ua, ub = XS_[a, PH_A], XS_[a, PH_B]
        vh, bh = AP_[a, HOSE_VOL], AP_[a, HOSE_BETA]
        out["oil"] += (va * G(pa) + vb * G(pb)) / beta + vh / bh * (G(ua) + G(ub))
        out["hose_flow"] += 0.5 * AP_[a, HOSE_I] * (XS_[a, QH_A] ** 2 + XS_[a, QH_B] ** 2)
        return True

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        import math

        s0 = (current or {}).get("bulk_modulus_scale", 1.0)
        grid = [s0 * f for f in (0.15, 0.35, 0.6, 1.5)] if current else [0.1, 0.3, 1.0, 2.0]
        return {"free": [("bulk_modulus_scale", 0.05, 3.0, True, s0 if current else math.nan, "")],
                "fixed": {"bulk_modulus_scale": s0}, "grid": [[v] for v in clip_grid(grid, 0.05, 3.0)]}


@njit(inline="always")
def _line_solve(h, u, qh, p, qv, dqv, ch, inert, r, cc, qdisp, lk, dlk):
    """One implicit step of a T-type line: hose node ``u``, line flow ``qh``, chamber ``p``.

        ch (u' - u)/h = qv + dqv (u' - u) - qh'
        I (qh' - qh)/h = u' - p' - r qh'
        cc (p' - p)/h = qh' - qdisp - lk - dlk (p' - p)
    """
    d1 = ch / h - dqv
    d3 = cc / h + dlk
    alpha = (ch / h * u + qv - dqv * u) / d1
    gamma = (cc / h * p - qdisp - lk + dlk * p) / d3
    qn = (inert / h * qh + alpha - gamma) / (inert / h + 1.0 / d1 + 1.0 / d3 + r)
    return alpha - qn / d1, qn, gamma + qn / d3


@njit(inline="always")
def _resistances(a, qha, qhb, AP):
    if AP[a, HOSE_TURB] != 0.0:
        return AP[a, HOSE_RTURB] * abs(qha), AP[a, HOSE_RTURB] * abs(qhb)
    return AP[a, HOSE_RLAM], AP[a, HOSE_RLAM]


@njit(inline="always")
def hose_node_pressures(a, pa, pb, AP, XS):
    """With the line dynamic, the valve ports see the hose's valve-end node."""
    return XS[a, PH_A], XS[a, PH_B]


@njit(inline="always")
def t_line_pressures(a, h, ua, ub, pa, pb, qva, dqva, qvb, dqvb, va, vb, qdisp_a, qdisp_b,
                     lk_a, dlk_a, lk_b, dlk_b, beta0, bulk, GP, AP, XS, XG, energy):
    """Node, line flow and chamber solved together (linearly implicit): stable for any hose."""
    fa = bulk(pa, GP)
    fb = bulk(pb, GP)
    vh = AP[a, HOSE_VOL]
    beta_h = AP[a, HOSE_BETA]
    cha = vh / (beta_h * bulk(ua, GP))
    chb = vh / (beta_h * bulk(ub, GP))
    cca = va / (beta0 * fa)
    ccb = vb / (beta0 * fb)
    inert = AP[a, HOSE_I]
    qha = XS[a, QH_A]
    qhb = XS[a, QH_B]
    ra, rb = _resistances(a, qha, qhb, AP)
    ua_n, qha_n, pa_n = _line_solve(h, ua, qha, pa, qva, dqva, cha, inert, ra, cca, qdisp_a, lk_a, dlk_a)
    ub_n, qhb_n, pb_n = _line_solve(h, ub, qhb, pb, qvb, dqvb, chb, inert, rb, ccb, qdisp_b, lk_b, dlk_b)
    XS[a, QH_A] = qha_n
    XS[a, QH_B] = qhb_n
    if energy:
        XG[XG_E_HOSE] += h * ra * qha_n * qha_n + h * rb * qhb_n * qhb_n
    return pa_n, pb_n, ua_n, ub_n, fa, fb


@njit(inline="always")
def store_line_nodes(a, ua_n, ub_n, qa_e, qb_e, AP, XS):
    XS[a, PH_A] = ua_n
    XS[a, PH_B] = ub_n


@njit(inline="always")
def follow_chambers(a, ua_n, ub_n, qa_e, qb_e, AP, XS):
    """Off: the node is the chamber and the line carries the valve's flow (states kept in step)."""
    XS[a, PH_A] = ua_n
    XS[a, PH_B] = ub_n
    XS[a, QH_A] = qa_e
    XS[a, QH_B] = qb_e


@njit(inline="always")
def t_line_derivatives(a, ua, ub, pa, pb, qva, qvb, va, vb, qdisp_a, qdisp_b, lk_a, lk_b, beta0, bulk, GP, AP, XS, dXS):
    """Reference solver: the T-line's node, flow and chamber derivatives."""
    qha = XS[a, QH_A]
    qhb = XS[a, QH_B]
    cha = AP[a, HOSE_VOL] / (AP[a, HOSE_BETA] * bulk(ua, GP))
    chb = AP[a, HOSE_VOL] / (AP[a, HOSE_BETA] * bulk(ub, GP))
    ra, rb = _resistances(a, qha, qhb, AP)
    inert = AP[a, HOSE_I]
    dXS[a, PH_A] = (qva - qha) / cha
    dXS[a, PH_B] = (qvb - qhb) / chb
    # cavitation floor (projected), as for the chambers
    if ua <= GP[P_MIN] and dXS[a, PH_A] < 0.0:
        dXS[a, PH_A] = 0.0
    if ub <= GP[P_MIN] and dXS[a, PH_B] < 0.0:
        dXS[a, PH_B] = 0.0
    dXS[a, QH_A] = (ua - pa - ra * qha) / inert
    dXS[a, QH_B] = (ub - pb - rb * qhb) / inert
    return (qha - qdisp_a - lk_a) / (va / (beta0 * bulk(pa, GP))), (qhb - qdisp_b - lk_b) / (vb / (beta0 * bulk(pb, GP)))
