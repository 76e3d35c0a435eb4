"""Reference solution of the same model with a variable-step stiff solver (scipy Radau/LSODA).

An independent implementation of the plant's continuous-time equations, ``dy/dt = f(t, y)``, built
from the same component functions (orifice, opening, linkage, friction, ...) but not from the
fixed-step kernel. With the command piecewise constant (delay, hysteresis and deadband applied
exactly at the switching instants) each constant piece is integrated to tight tolerance. The tests
compare the kernel against it; ``hydrohil bench`` reports the speed ratio.

The cavitation floor is a projection (dp/dt clipped at vapour pressure) where the kernel clamps;
sensor models are not applied (the reference returns true states).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.integrate import solve_ivp

from .components.cylinder import cylinder_length
from .components.directional_valve import opening, orifice
from .components.labview_adaptation import adapt
from .components.amplifier import amplifier_current
from .dynamics.rigid_body import crba, kinematics, ltl_factor, ltl_solve, rnea
from .effects.bulk_modulus import bulk_factor
from .effects.coulomb_friction import friction_torque
from .effects.deadband import dead_zone
from .effects.hysteresis import play
from .effects.leakage import chamber_leakage
from .kernel.layout import *  # noqa: F403

NA_STATES = 13  # I_A, I_B, X, V, XL, PA, PB, PHA, PHB, QHA, QHB, THA, OMA


@njit(cache=True)
def rhs(y, ueff, tree, DP, AP, GP, ws, dy):
    parent, R_tree, p_tree, axis, mass, com, inertia, gravity = tree
    (Rw, ow, aw, cw, Iw, tmp33, w, dw, ao, F, N, mc, hc, Ic, M, bias, zero, tau) = ws
    n = parent.shape[0]
    na = AP.shape[0]
    q = y[0:n]
    qd = y[n:2 * n]
    kinematics(parent, R_tree, p_tree, axis, com, inertia, q, Rw, ow, aw, cw, Iw, tmp33)
    crba(parent, mass, ow, aw, cw, Iw, mc, hc, Ic, M)
    rnea(parent, mass, gravity, ow, aw, cw, Iw, qd, zero, 1.0, w, dw, ao, F, N, bias)
    for i in range(n):
        tau[i] = -bias[i] - DP[i, DP_DAMPING] * qd[i]
        if q[i] > DP[i, DP_UPPER]:
            f = -DP[i, DP_STOP_K] * (q[i] - DP[i, DP_UPPER]) - DP[i, DP_STOP_C] * qd[i]
            if f < 0.0:
                tau[i] += f
        elif q[i] < DP[i, DP_LOWER]:
            f = -DP[i, DP_STOP_K] * (q[i] - DP[i, DP_LOWER]) - DP[i, DP_STOP_C] * qd[i]
            if f > 0.0:
                tau[i] += f
    p_s = y[2 * n + NA_STATES * na] if GP[GP_PUMP_QMAX] > 0.0 else GP[GP_P_SUPPLY] * GP[GP_SUPPLY_SAG]
    p_t = GP[GP_P_TANK]
    q_supply = 0.0
    for a in range(na):
        b = 2 * n + NA_STATES * a
        dof = int(AP[a, AP_DOF])
        ia, ib, x, v, xl = y[b], y[b + 1], y[b + 2], y[b + 3], y[b + 4]
        pa, pb = y[b + 5], y[b + 6]
        comp = AP[a, AP_E_COMPLIANCE] != 0.0
        th = y[b + 11] if comp else q[dof]
        om = y[b + 12] if comp else qd[dof]
        # command chain
        va, vb = adapt(ueff[a])
        ira = amplifier_current(va, AP[a, AP_AMP_GAIN], AP[a, AP_AMP_IMAX])
        irb = amplifier_current(vb, AP[a, AP_AMP_GAIN], AP[a, AP_AMP_IMAX])
        ts = AP[a, AP_SOL_TAU]
        wn = AP[a, AP_SPOOL_WN]
        dy[b] = (ira - ia) / ts
        dy[b + 1] = (irb - ib) / ts
        dy[b + 2] = v
        dy[b + 3] = wn * wn * (AP[a, AP_SPOOL_GAIN] * (ia - ib) - x) - 2.0 * AP[a, AP_SPOOL_ZETA] * wn * v
        dy[b + 4] = (x - xl) / AP[a, AP_LAG_TAU]
        if AP[a, AP_F_SPOOL_STUCK] != 0.0:
            dy[b + 2] = 0.0
            dy[b + 3] = 0.0
            dy[b + 4] = 0.0
        s = xl if AP[a, AP_E_SPOOL_LAG] != 0.0 else x
        lim = AP[a, AP_SPOOL_LIMIT]
        s = min(max(s, -lim), lim)
        # actuator
        if AP[a, AP_KIND] == 0.0:
            L, arm = cylinder_length(th, AP[a, AP_LK_C0], AP[a, AP_LK_D1], AP[a, AP_LK_D2])
            xc = L - AP[a, AP_LK_LMIN]
            vol_a = AP[a, AP_VDEAD_A] + AP[a, AP_AREA_A] * xc
            vol_b = AP[a, AP_VDEAD_B] + AP[a, AP_AREA_B] * (AP[a, AP_STROKE] - xc)
            qda = AP[a, AP_AREA_A] * arm * om
            qdb = -AP[a, AP_AREA_B] * arm * om
            tau_h = (pa * AP[a, AP_AREA_A] - pb * AP[a, AP_AREA_B]) * arm
            visc = AP[a, AP_VISC] * arm * arm
        else:
            vol_a = AP[a, AP_VDEAD_A]
            vol_b = AP[a, AP_VDEAD_B]
            qda = AP[a, AP_AREA_A] * om
            qdb = -AP[a, AP_AREA_A] * om
            tau_h = (pa - pb) * AP[a, AP_AREA_A]
            visc = AP[a, AP_VISC]
        if comp:
            k = AP[a, AP_COMP_K]
            c = AP[a, AP_COMP_C]
            spring = k * (th - q[dof]) + c * (om - qd[dof])
            dy[b + 11] = om
            dy[b + 12] = (tau_h - visc * om - spring) / AP[a, AP_COMP_JA]
            tau[dof] += spring
        else:
            dy[b + 11] = 0.0
            dy[b + 12] = 0.0
            tau[dof] += tau_h - visc * qd[dof]
        if AP[a, AP_E_COULOMB] != 0.0:
            tf, _ = friction_torque(qd[dof], AP[a, AP_COUL_TORQUE], AP[a, AP_COUL_VEL])
            tau[dof] += tf
        line = AP[a, AP_E_LINE] != 0.0
        ua = y[b + 7] if line else pa
        ub = y[b + 8] if line else pb
        kv = AP[a, AP_KV]
        kvn = kv * AP[a, AP_ASYM_RATIO] if AP[a, AP_E_ASYM] != 0.0 else kv
        sp = s if s > 0.0 else 0.0
        sn = -s if s < 0.0 else 0.0
        g_pa = kv * (opening(sp, AP[a, AP_OVERLAP], AP[a, AP_POLY1], AP[a, AP_POLY2], AP[a, AP_POLY3]) + AP[a, AP_NULL_LEAK])
        g_pb = kvn * (opening(sn, AP[a, AP_OVERLAP], AP[a, AP_POLY1], AP[a, AP_POLY2], AP[a, AP_POLY3]) + AP[a, AP_NULL_LEAK])
        tr = AP[a, AP_DP_TR]
        q_pa = g_pa * orifice(p_s - ua, tr)[0]
        q_at = g_pb * orifice(ua - p_t, tr)[0]
        q_pb = g_pb * orifice(p_s - ub, tr)[0]
        q_bt = g_pa * orifice(ub - p_t, tr)[0]
        if AP[a, AP_E_FLOWSAT] != 0.0:
            qm = AP[a, AP_FLOWSAT_Q]
            q_pa = min(max(q_pa, -qm), qm)
            q_pb = min(max(q_pb, -qm), qm)
        qva = q_pa - q_at
        qvb = q_pb - q_bt
        if AP[a, AP_F_BURST_KV] > 0.0:
            qva -= AP[a, AP_F_BURST_KV] * orifice(ua - p_t, tr)[0]
        q_supply += q_pa + q_pb
        lk_a, lk_b, _, _ = chamber_leakage(
            pa, pb, p_t, AP[a, AP_LEAK_INT] if AP[a, AP_E_LEAK] != 0.0 else 0.0,
            AP[a, AP_LEAK_EXT] if AP[a, AP_E_LEAK] != 0.0 else 0.0, AP[a, AP_F_LEAK_A], AP[a, AP_F_LEAK_B],
            AP[a, AP_RELIEF_P], AP[a, AP_RELIEF_K])
        beta = GP[GP_BETA]
        fa = bulk_factor(pa, GP[GP_E_BULK], GP[GP_BULK_SCALE], GP[GP_BULK_PAIR], GP[GP_P_ATM])
        fb = bulk_factor(pb, GP[GP_E_BULK], GP[GP_BULK_SCALE], GP[GP_BULK_PAIR], GP[GP_P_ATM])
        vh = AP[a, AP_HOSE_VOL]
        bh = AP[a, AP_HOSE_BETA]
        if line:
            qha, qhb = y[b + 9], y[b + 10]
            cha = vh / (bh * bulk_factor(ua, GP[GP_E_BULK], GP[GP_BULK_SCALE], GP[GP_BULK_PAIR], GP[GP_P_ATM]))
            chb = vh / (bh * bulk_factor(ub, GP[GP_E_BULK], GP[GP_BULK_SCALE], GP[GP_BULK_PAIR], GP[GP_P_ATM]))
            if AP[a, AP_HOSE_TURB] != 0.0:
                ra = AP[a, AP_HOSE_RTURB] * abs(qha)
                rb = AP[a, AP_HOSE_RTURB] * abs(qhb)
            else:
                ra = AP[a, AP_HOSE_RLAM]
                rb = ra
            I = AP[a, AP_HOSE_I]
            dy[b + 7] = (qva - qha) / cha
            dy[b + 8] = (qvb - qhb) / chb
            dy[b + 9] = (ua - pa - ra * qha) / I
            dy[b + 10] = (ub - pb - rb * qhb) / I
            dy[b + 5] = (qha - qda - lk_a) / (vol_a / (beta * fa))
            dy[b + 6] = (qhb - qdb - lk_b) / (vol_b / (beta * fb))
        else:
            ca = vol_a / (beta * fa) + vh / (bh * fa)
            cb = vol_b / (beta * fb) + vh / (bh * fb)
            dy[b + 5] = (qva - qda - lk_a) / ca
            dy[b + 6] = (qvb - qdb - lk_b) / cb
            dy[b + 7] = dy[b + 5]
            dy[b + 8] = dy[b + 6]
            dy[b + 9] = 0.0
            dy[b + 10] = 0.0
        # cavitation floor (projected): a chamber or hose node at vapour pressure cannot fall further
        for c in range(5, 9):
            if y[b + c] <= GP[GP_P_MIN] and dy[b + c] < 0.0:
                dy[b + c] = 0.0
    for i in range(n):
        dy[i] = qd[i]
    ltl_factor(parent, M)
    ltl_solve(parent, M, tau)
    for i in range(n):
        dy[n + i] = tau[i]
    if GP[GP_PUMP_QMAX] > 0.0:
        ps = y[2 * n + NA_STATES * na]
        xr = (GP[GP_P_SUPPLY] * GP[GP_SUPPLY_SAG] - ps) / GP[GP_PUMP_BAND]
        qp = GP[GP_PUMP_QMAX] * min(max(xr, 0.0), 1.0)
        qr = GP[GP_SUPPLY_RELIEF_K] * (ps - GP[GP_SUPPLY_RELIEF_P]) if ps > GP[GP_SUPPLY_RELIEF_P] else 0.0
        dy[2 * n + NA_STATES * na] = (qp - q_supply - qr) / GP[GP_SUPPLY_C]


def _effective_commands(ctx, times, U):
    """Exact piecewise-constant effective command (after delay, hysteresis, deadband) per actuator.

    Returns (breakpoints [M+1], values [M, n_act]) covering [times[0], times[-1]]."""
    AP = ctx.AP
    na = AP.shape[0]
    t0, t_end = times[0], times[-1]
    bps = {t0, t_end}
    for a in range(na):
        d = AP[a, AP_DELAY] if AP[a, AP_E_DELAY] != 0.0 else 0.0
        for t in times[:-1]:
            if t0 < t + d < t_end:
                bps.add(t + d)
    bps = np.array(sorted(bps))
    mids = 0.5 * (bps[:-1] + bps[1:])
    vals = np.zeros((mids.size, na))
    for a in range(na):
        d = AP[a, AP_DELAY] if AP[a, AP_E_DELAY] != 0.0 else 0.0
        lo, hi = AP[a, AP_U_MIN], AP[a, AP_U_MAX]
        state = ctx.XS[a, XS_U_HYST]
        for m, tm in enumerate(mids):
            k = np.searchsorted(times, tm - d, side="right") - 1
            u = 0.0 if k < 0 else float(np.clip(U[k, a], lo, hi))
            if AP[a, AP_E_HYST] != 0.0:
                state = play(state, u, 0.5 * AP[a, AP_HYST_WIDTH])
                u = state
            if AP[a, AP_E_DEADBAND] != 0.0:
                u = dead_zone(u, AP[a, AP_DB_WIDTH])
            vals[m, a] = u
    return bps, vals


def initial_vector(ctx) -> np.ndarray:
    n, na = ctx.spec.tree.n, len(ctx.spec.joints)
    y = np.zeros(2 * n + NA_STATES * na + 1)
    y[:n], y[n:2 * n] = ctx.XQ[0], ctx.XQ[1]
    for a in range(na):
        b = 2 * n + NA_STATES * a
        y[b:b + 11] = ctx.XS[a, XS_I_A:XS_QH_B + 1]
        y[b + 11], y[b + 12] = ctx.XS[a, XS_TH_A], ctx.XS[a, XS_OM_A]
    y[-1] = ctx.XG[XG_P_S]
    return y


def solve_reference(ctx, times, U, *, method: str = "Radau", rtol: float = 1e-8, max_step: float = np.inf):
    """Integrate the context's model from its current state on ``times`` with commands ``U`` (ZOH).

    Returns (q [N, n_dof] true angles, y [N, n_states])."""
    times = np.asarray(times, dtype=float)
    U = np.asarray(U, dtype=float)
    lw = ctx.lowered
    t = ctx.spec.tree
    tree = (t.parent, t.R_tree, t.p_tree, t.axis, lw.mass, lw.com, lw.inertia, t.gravity)
    n, na = t.n, len(ctx.spec.joints)
    ws = (np.zeros((n, 3, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3)),
          np.zeros((3, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)),
          np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, n)),
          np.zeros(n), np.zeros(n), np.zeros(n))
    y = initial_vector(ctx)
    atol = np.empty_like(y)
    atol[:n] = 1e-10
    atol[n:2 * n] = 1e-9
    for a in range(na):
        b = 2 * n + NA_STATES * a
        atol[b:b + 2] = 1e-10        # currents (A)
        atol[b + 2:b + 5] = 1e-10    # spool (stroke fraction, and per second)
        atol[b + 3] = 1e-8
        atol[b + 5:b + 9] = 1e-2     # pressures (Pa)
        atol[b + 9:b + 11] = 1e-12   # hose flows (m^3/s)
        atol[b + 11:b + 13] = 1e-10
    atol[-1] = 1e-2
    bps, vals = _effective_commands(ctx, times, U)
    out = np.zeros((times.size, y.size))
    out[0] = y
    dy = np.zeros_like(y)

    def f(_t, yy, ueff):
        rhs(yy, ueff, tree, ctx.DP, ctx.AP, ctx.GP, ws, dy)
        return dy.copy()

    for m in range(bps.size - 1):
        ta, tb = bps[m], bps[m + 1]
        sel = np.flatnonzero((times > ta) & (times <= tb))
        ueff = vals[m].copy()
        t_eval = np.append(times[sel][times[sel] < tb], tb)
        sol = solve_ivp(f, (ta, tb), y, method=method, rtol=rtol, atol=atol, t_eval=t_eval, args=(ueff,),
                        max_step=max_step)
        if not sol.success:
            raise RuntimeError(f"reference solver failed at t = {ta:.4f}: {sol.message}")
        if sel.size:
            out[sel] = sol.y.T[-sel.size:] if times[sel][-1] == tb else sol.y.T[:sel.size]
        y = sol.y[:, -1]
    return out[:, :n], out
