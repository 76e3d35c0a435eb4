"""The compiled plant step: one call advances the whole arm by any number of output steps.

Integration scheme per substep ``h`` (chosen for stiff hydraulics, deterministic, no allocation):

1. Command path: delay line (substep-averaged, so fractional delays are smooth), hysteresis play,
   deadband, LabVIEW adaptation, amplifiers. The linear chain coil currents -> spool -> spool_lag
   is advanced *exactly* with its zero-order-hold matrix exponential.
2. Mechanics, symplectic Euler with linearly implicit damping: actuator torques from the old
   pressures, ``(M + h D) dqd = h (tau - bias)``, ``q += h qd_new``. ``M`` and the Coriolis/gravity
   bias are refreshed once per output step (or every ``rb_every`` substeps): joint speeds of
   hydraulic arms are low, so they barely change within a millisecond, and this keeps the cost of a
   7-DOF arm near that of its hydraulics.
3. Pressures, linearly implicit in each node's own pressure (valve orifice, leakage, relief) with
   the new actuator velocities: ``p += h (Q(p) - Q_disp) / C / (1 - h dQ/dp / C)``. With hoses on,
   the line flows are updated first from the old pressures (T-type line, symplectic in L-C).
4. Supply node (flow-limited pump), backlash state, time.

This symplectic/implicit split is stable at the orifice stiffness and accurate on the lightly
damped hydro-mechanical modes (research note: 'performance-measurements', scheme SIP); the tests
compare it with scipy's Radau at rtol 1e-8.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..components.amplifier import amplifier_current
from ..components.cylinder import cylinder_length
from ..components.directional_valve import opening, orifice
from ..components.labview_adaptation import adapt
from ..components.spool import command_chain_matrix, expm_augmented
from ..dynamics.rigid_body import crba, kinematics, ltl_factor, ltl_solve, rnea
from ..effects.bulk_modulus import bulk_factor
from ..effects.coulomb_friction import friction_torque
from ..effects.deadband import dead_zone
from ..effects.hysteresis import play
from ..effects.leakage import chamber_leakage
from .layout import *  # noqa: F403 - column constants (compile-time)

_NJ = dict(cache=True, nogil=True)

# temporary per-actuator columns (ws["act"])
T_S = 0          # metering spool position this substep
T_TAU = 1        # actuator torque on the link
T_QS = 2         # flow drawn from the supply by this valve (m^3/s), for the supply node
T_DQS = 3        # its slope wrt supply pressure
T_N = 4


@njit(inline="always", **_NJ)
def _next_uniform(rng):
    # xorshift64* (Vigna 2016): deterministic, seedable, no global state
    x = rng[0]
    x ^= x >> np.uint64(12)
    x ^= x << np.uint64(25)
    x ^= x >> np.uint64(27)
    rng[0] = x
    r = x * np.uint64(2685821657736338717)
    return ((r >> np.uint64(11)) + np.uint64(1)) * (1.0 / 9007199254740994.0)


@njit(**_NJ)
def gauss(rng):
    """Standard normal deviate (Box-Muller)."""
    u1 = _next_uniform(rng)
    u2 = _next_uniform(rng)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@njit(**_NJ)
def delayed_command(a, t0, t1, HT, HU, XG, XS):
    """Mean of the command of actuator ``a`` over [t0, t1] from the event history (ZOH events)."""
    count = int(XG[XG_HIST_COUNT])
    cap = HT.shape[0]
    c = int(XS[a, XS_CURSOR])
    # advance the cursor to the last event at or before t0
    while c + 1 < count and HT[(c + 1) % cap] <= t0:
        c += 1
    if c >= 0 and c < count - cap:
        XG[XG_ERROR] = ERR_DELAY_OVERRUN
        c = count - cap
    XS[a, XS_CURSOR] = c
    acc = 0.0
    tau = t0
    j = c
    while tau < t1:
        val = HU[j % cap, a] if j >= 0 else 0.0
        nxt = HT[(j + 1) % cap] if j + 1 < count else 1e300
        end = nxt if nxt < t1 else t1
        if end > tau:
            acc += val * (end - tau)
            tau = end
        j += 1
    return acc / (t1 - t0)


@njit(**_NJ)
def refresh_command_chain(AP, h, Acc, Bcc, expw):
    """Recompute the exact discretisation of every actuator's command chain for substep ``h``."""
    for a in range(AP.shape[0]):
        if abs(AP[a, AP_CMD_H] - h) <= 1e-9 * h:  # grids from arange differ in the last bits
            continue
        command_chain_matrix(AP[a, AP_SOL_TAU], AP[a, AP_SPOOL_WN], AP[a, AP_SPOOL_ZETA],
                             AP[a, AP_SPOOL_GAIN], AP[a, AP_LAG_TAU], Acc, Bcc)
        expm_augmented(Acc, Bcc, h, expw, AP[a, AP_PHI:AP_PHI + 25], AP[a, AP_GAM:AP_GAM + 10])
        AP[a, AP_CMD_H] = h


@njit(**_NJ)
def sample_sensors(AP, q, XS, rng, Ya_row, u_row):
    """Read every joint sensor like the cFP analog inputs do and fill one output row."""
    for a in range(AP.shape[0]):
        Ya_row[a, YA_U] = u_row[a]
        Ya_row[a, YA_P_A] = XS[a, XS_P_A]
        Ya_row[a, YA_P_B] = XS[a, XS_P_B]
        Ya_row[a, YA_SPOOL] = XS[a, XS_SPOOL_X]
        Ya_row[a, YA_Q_A] = XS[a, XS_Q_A]
        if AP[a, AP_SENSED] == 0.0:
            Ya_row[a, YA_SENS_V] = math.nan
            Ya_row[a, YA_ANGLE] = math.nan
            continue
        dof = int(AP[a, AP_DOF])
        th = XS[a, XS_Y_BACK] if AP[a, AP_E_BACKLASH] != 0.0 else q[dof]
        th = AP[a, AP_SENS_GAIN] * th + AP[a, AP_SENS_OFFSET]
        A = AP[a, AP_POT_A]
        B = AP[a, AP_POT_B]
        v = (th - B) / A
        if AP[a, AP_POT_NOISE] > 0.0:
            v += AP[a, AP_POT_NOISE] * gauss(rng)
        mode = AP[a, AP_F_SENS_MODE]
        if mode == 1.0:
            v = AP[a, AP_F_SENS_VALUE]
        elif mode == 2.0:
            v += AP[a, AP_F_SENS_NOISE] * gauss(rng)
        v += AP[a, AP_F_SENS_OFFSET]
        lsb = AP[a, AP_POT_LSB]
        vmin = AP[a, AP_POT_VMIN]
        vmax = AP[a, AP_POT_VMAX]
        if lsb > 0.0:
            v = vmin + math.floor((v - vmin) / lsb + 0.5) * lsb
        if v < vmin:
            v = vmin
        elif v > vmax:
            v = vmax
        XS[a, XS_SENS_V] = v
        XS[a, XS_SENS_ANGLE] = A * v + B
        Ya_row[a, YA_SENS_V] = v
        Ya_row[a, YA_ANGLE] = A * v + B


@njit(inline="always", **_NJ)
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


@njit(**_NJ)
def _substep(h, t, u_in, tree, DP, AP, GP, XQ, XS, XG, HT, HU, ws, refresh_rb):
    parent, R_tree, p_tree, axis, mass, com, inertia, gravity = tree
    (Rw, ow, aw, cw, Iw, tmp33, w, dw, ao, F, N, mc, hc, Ic, M, Lf, bias, zero, rhs, Dlin, Ffr, Sfr, Tact, Kst, act) = ws
    n = parent.shape[0]
    na = AP.shape[0]
    q = XQ[0]
    qd = XQ[1]
    energy = GP[GP_ENERGY] != 0.0
    p_t = GP[GP_P_TANK]
    p_atm = GP[GP_P_ATM]
    beta0 = GP[GP_BETA]
    bulk_on = GP[GP_E_BULK]
    bulk_s = GP[GP_BULK_SCALE]
    bulk_pa = GP[GP_BULK_PAIR]
    p_min = GP[GP_P_MIN]
    p_s = XG[XG_P_S]

    if refresh_rb:
        kinematics(parent, R_tree, p_tree, axis, com, inertia, q, Rw, ow, aw, cw, Iw, tmp33)
        crba(parent, mass, ow, aw, cw, Iw, mc, hc, Ic, M)
        rnea(parent, mass, gravity, ow, aw, cw, Iw, qd, zero, 1.0, w, dw, ao, F, N, bias)

    # ---- 1. command path ---------------------------------------------------------------------
    for a in range(na):
        if DP[int(AP[a, AP_DOF]), DP_LOCKED] != 0.0:
            act[a, T_S] = 0.0
            continue
        if AP[a, AP_E_DELAY] != 0.0:
            d = AP[a, AP_DELAY]
            u = delayed_command(a, t - d, t + h - d, HT, HU, XG, XS)
        else:
            u = u_in[a]
        if AP[a, AP_E_HYST] != 0.0:
            u = play(XS[a, XS_U_HYST], u, 0.5 * AP[a, AP_HYST_WIDTH])
            XS[a, XS_U_HYST] = u
        else:
            XS[a, XS_U_HYST] = u
        if AP[a, AP_E_DEADBAND] != 0.0:
            u = dead_zone(u, AP[a, AP_DB_WIDTH])
        XS[a, XS_U_EFF] = u
        va, vb = adapt(u)
        ira = amplifier_current(va, AP[a, AP_AMP_GAIN], AP[a, AP_AMP_IMAX])
        irb = amplifier_current(vb, AP[a, AP_AMP_GAIN], AP[a, AP_AMP_IMAX])
        z0 = XS[a, XS_I_A]
        z1 = XS[a, XS_I_B]
        z2 = XS[a, XS_SPOOL_X]
        z3 = XS[a, XS_SPOOL_V]
        z4 = XS[a, XS_LAG_X]
        x_old = z4 if AP[a, AP_E_SPOOL_LAG] != 0.0 else z2
        for r in range(5):
            b = AP_PHI + 5 * r
            XS[a, r] = (AP[a, b] * z0 + AP[a, b + 1] * z1 + AP[a, b + 2] * z2 + AP[a, b + 3] * z3
                        + AP[a, b + 4] * z4 + AP[a, AP_GAM + 2 * r] * ira + AP[a, AP_GAM + 2 * r + 1] * irb)
        if AP[a, AP_F_SPOOL_STUCK] != 0.0:
            XS[a, XS_SPOOL_X] = AP[a, AP_F_SPOOL_POS]
            XS[a, XS_SPOOL_V] = 0.0
            XS[a, XS_LAG_X] = AP[a, AP_F_SPOOL_POS]
            x_old = AP[a, AP_F_SPOOL_POS]
        x_new = XS[a, XS_LAG_X] if AP[a, AP_E_SPOOL_LAG] != 0.0 else XS[a, XS_SPOOL_X]
        s = 0.5 * (x_old + x_new)
        lim = AP[a, AP_SPOOL_LIMIT]
        if s > lim:
            s = lim
        elif s < -lim:
            s = -lim
        act[a, T_S] = s

    # ---- 2. mechanics ------------------------------------------------------------------------
    # F(qd) = -bias + tau_act - D qd + stops + friction; (M + h dF/dqd) dqd = h F(qd_old)
    for i in range(n):
        rhs[i] = -bias[i] - DP[i, DP_DAMPING] * qd[i]
        Dlin[i] = DP[i, DP_DAMPING]
        Ffr[i] = 0.0
        Sfr[i] = 0.0
        Tact[i] = 0.0
        lo = DP[i, DP_LOWER]
        hi = DP[i, DP_UPPER]
        Kst[i] = 0.0
        if q[i] > hi:  # end stop: spring-damper while penetrating, never pulling
            f = -DP[i, DP_STOP_K] * (q[i] - hi) - DP[i, DP_STOP_C] * qd[i]
            if f < 0.0:
                rhs[i] += f
                Dlin[i] += DP[i, DP_STOP_C]
                Kst[i] = DP[i, DP_STOP_K]
        elif q[i] < lo:
            f = -DP[i, DP_STOP_K] * (q[i] - lo) - DP[i, DP_STOP_C] * qd[i]
            if f > 0.0:
                rhs[i] += f
                Dlin[i] += DP[i, DP_STOP_C]
                Kst[i] = DP[i, DP_STOP_K]
    for a in range(na):
        dof = int(AP[a, AP_DOF])
        if DP[dof, DP_LOCKED] != 0.0:
            act[a, T_TAU] = 0.0
            continue
        comp = AP[a, AP_E_COMPLIANCE] != 0.0
        th = XS[a, XS_TH_A] if comp else q[dof]
        om = XS[a, XS_OM_A] if comp else qd[dof]
        if AP[a, AP_KIND] == 0.0:
            L, arm = cylinder_length(th, AP[a, AP_LK_C0], AP[a, AP_LK_D1], AP[a, AP_LK_D2])
            tau_h = (XS[a, XS_P_A] * AP[a, AP_AREA_A] - XS[a, XS_P_B] * AP[a, AP_AREA_B]) * arm
            visc = AP[a, AP_VISC] * arm * arm
        else:
            tau_h = (XS[a, XS_P_A] - XS[a, XS_P_B]) * AP[a, AP_AREA_A]
            visc = AP[a, AP_VISC]
        if comp:
            # actuator side J_a th'' = tau_h - visc om - k (th - q) - c (om - qd), implicit in om
            k = AP[a, AP_COMP_K]
            c = AP[a, AP_COMP_C]
            ja = AP[a, AP_COMP_JA]
            om_new = (om + h * (tau_h - k * (th - q[dof]) + c * qd[dof]) / ja) / (1.0 + h * (visc + c) / ja)
            th_new = th + h * om_new
            if energy:
                XG[XG_E_MECH] += h * visc * om_new * om_new
            XS[a, XS_OM_A] = om_new
            XS[a, XS_TH_A] = th_new
            link = k * (th_new - q[dof]) + c * (om_new - qd[dof])
            rhs[dof] += link
            Dlin[dof] += c
            act[a, T_TAU] = link
            Tact[dof] += link
        else:
            rhs[dof] += tau_h - visc * qd[dof]
            Dlin[dof] += visc
            act[a, T_TAU] = tau_h
            Tact[dof] += tau_h
        if AP[a, AP_E_COULOMB] != 0.0:
            tf, slope = friction_torque(qd[dof], AP[a, AP_COUL_TORQUE], AP[a, AP_COUL_VEL])
            rhs[dof] += tf
            Ffr[dof] += tf
            Sfr[dof] += slope
    for i in range(n):
        for j in range(n):
            Lf[i, j] = M[i, j]
        Lf[i, i] += h * (Dlin[i] - Sfr[i]) + h * h * Kst[i]   # stop spring implicit: q_new = q + h qd_new
    for i in range(n):
        if DP[i, DP_LOCKED] != 0.0:  # held rigid: qdd = 0, the free joints see the reduced dynamics
            for j in range(n):
                Lf[i, j] = 0.0
                Lf[j, i] = 0.0
            Lf[i, i] = 1.0
            rhs[i] = 0.0
            qd[i] = 0.0
    ltl_factor(parent, Lf)
    ltl_solve(parent, Lf, rhs)  # rhs now holds qdd
    for i in range(n):
        qd_new = qd[i] + h * rhs[i]
        if energy:
            # dissipated power of the linearly implicit terms, at the mean velocity of the step
            vavg = 0.5 * (qd[i] + qd_new)
            XG[XG_E_MECH] += h * (Dlin[i] * qd_new - Ffr[i] - Sfr[i] * (qd_new - qd[i])) * vavg
            XG[XG_E_ACT] += h * Tact[i] * vavg
        qd[i] = qd_new
        q[i] += h * qd_new

    # ---- 3. pressures -------------------------------------------------------------------------
    q_supply = 0.0
    dq_supply = 0.0
    ideal_pump = GP[GP_PUMP_QMAX] <= 0.0
    for a in range(na):
        dof = int(AP[a, AP_DOF])
        if DP[dof, DP_LOCKED] != 0.0:
            act[a, T_QS] = 0.0
            continue
        if AP[a, AP_E_COMPLIANCE] != 0.0:
            th = XS[a, XS_TH_A]
            om = XS[a, XS_OM_A]
        else:
            th = q[dof]
            om = qd[dof]
            XS[a, XS_TH_A] = th
            XS[a, XS_OM_A] = om
        if AP[a, AP_KIND] == 0.0:
            L, arm = cylinder_length(th, AP[a, AP_LK_C0], AP[a, AP_LK_D1], AP[a, AP_LK_D2])
            x = L - AP[a, AP_LK_LMIN]
            xd = arm * om
            va_ = AP[a, AP_VDEAD_A] + AP[a, AP_AREA_A] * x
            vb_ = AP[a, AP_VDEAD_B] + AP[a, AP_AREA_B] * (AP[a, AP_STROKE] - x)
            qdisp_a = AP[a, AP_AREA_A] * xd
            qdisp_b = -AP[a, AP_AREA_B] * xd
        else:
            va_ = AP[a, AP_VDEAD_A]
            vb_ = AP[a, AP_VDEAD_B]
            qdisp_a = AP[a, AP_AREA_A] * om
            qdisp_b = -AP[a, AP_AREA_A] * om
        if va_ < 1e-9:
            va_ = 1e-9
        if vb_ < 1e-9:
            vb_ = 1e-9
        pa = XS[a, XS_P_A]
        pb = XS[a, XS_P_B]
        line = AP[a, AP_E_LINE] != 0.0
        # valve ports see the hose node when the line is dynamic, the chamber otherwise
        if line:
            ua = XS[a, XS_PH_A]
            ub = XS[a, XS_PH_B]
        else:
            ua = pa
            ub = pb
        # --- valve edges
        s = act[a, T_S]
        kv = AP[a, AP_KV]
        sp = s if s > 0.0 else 0.0
        sn = -s if s < 0.0 else 0.0
        ov = AP[a, AP_OVERLAP]
        c1 = AP[a, AP_POLY1]
        c2 = AP[a, AP_POLY2]
        c3 = AP[a, AP_POLY3]
        leak0 = AP[a, AP_NULL_LEAK]
        kvn = kv * AP[a, AP_ASYM_RATIO] if AP[a, AP_E_ASYM] != 0.0 else kv
        g_pa = kv * (opening(sp, ov, c1, c2, c3) + leak0)    # P->A and B->T
        g_pb = kvn * (opening(sn, ov, c1, c2, c3) + leak0)   # P->B and A->T
        tr = AP[a, AP_DP_TR]
        f_pa, d_pa = orifice(p_s - ua, tr)
        f_at, d_at = orifice(ua - p_t, tr)
        f_pb, d_pb = orifice(p_s - ub, tr)
        f_bt, d_bt = orifice(ub - p_t, tr)
        q_pa = g_pa * f_pa
        q_at = g_pb * f_at
        q_pb = g_pb * f_pb
        q_bt = g_pa * f_bt
        dq_pa = -g_pa * d_pa          # d q_pa / d ua
        dq_at = g_pb * d_at           # d q_at / d ua
        dq_pb = -g_pb * d_pb
        dq_bt = g_pa * d_bt
        if AP[a, AP_E_FLOWSAT] != 0.0:
            qmax = AP[a, AP_FLOWSAT_Q]
            if abs(q_pa) > qmax:
                q_pa = qmax if q_pa > 0.0 else -qmax
                dq_pa = 0.0
            if abs(q_pb) > qmax:
                q_pb = qmax if q_pb > 0.0 else -qmax
                dq_pb = 0.0
        qva = q_pa - q_at             # into line A
        qvb = q_pb - q_bt
        dqva = dq_pa - dq_at          # <= 0
        dqvb = dq_pb - dq_bt
        # hose burst (fault): orifice from line A to tank
        if AP[a, AP_F_BURST_KV] > 0.0:
            fb, db = orifice(ua - p_t, tr)
            qva -= AP[a, AP_F_BURST_KV] * fb
            dqva -= AP[a, AP_F_BURST_KV] * db
        # --- leakage (chambers): internal A->B, external and fault leaks to tank, port reliefs
        lk_a, lk_b, dlk_a, dlk_b = chamber_leakage(
            pa, pb, p_t, AP[a, AP_LEAK_INT] if AP[a, AP_E_LEAK] != 0.0 else 0.0,
            AP[a, AP_LEAK_EXT] if AP[a, AP_E_LEAK] != 0.0 else 0.0, AP[a, AP_F_LEAK_A], AP[a, AP_F_LEAK_B],
            AP[a, AP_RELIEF_P], AP[a, AP_RELIEF_K])
        # --- capacitances
        beta_h = AP[a, AP_HOSE_BETA]
        fa = bulk_factor(pa, bulk_on, bulk_s, bulk_pa, p_atm)
        fb_ = bulk_factor(pb, bulk_on, bulk_s, bulk_pa, p_atm)
        vh = AP[a, AP_HOSE_VOL]
        if line:
            cha = vh / (beta_h * bulk_factor(ua, bulk_on, bulk_s, bulk_pa, p_atm))
            chb = vh / (beta_h * bulk_factor(ub, bulk_on, bulk_s, bulk_pa, p_atm))
            cca = va_ / (beta0 * fa)
            ccb = vb_ / (beta0 * fb_)
            inert = AP[a, AP_HOSE_I]
            qha = XS[a, XS_QH_A]
            qhb = XS[a, XS_QH_B]
            if AP[a, AP_HOSE_TURB] != 0.0:
                ra = AP[a, AP_HOSE_RTURB] * abs(qha)
                rb = AP[a, AP_HOSE_RTURB] * abs(qhb)
            else:
                ra = AP[a, AP_HOSE_RLAM]
                rb = ra
            # node, line flow and chamber solved together (linearly implicit): stable for any hose
            ua_n, qha_n, pa_n = _line_solve(h, ua, qha, pa, qva, dqva, cha, inert, ra, cca, qdisp_a, lk_a, dlk_a)
            ub_n, qhb_n, pb_n = _line_solve(h, ub, qhb, pb, qvb, dqvb, chb, inert, rb, ccb, qdisp_b, lk_b, dlk_b)
            XS[a, XS_QH_A] = qha_n
            XS[a, XS_QH_B] = qhb_n
            if energy:
                XG[XG_E_HOSE] += h * ra * qha_n * qha_n + h * rb * qhb_n * qhb_n
        else:
            ca = va_ / (beta0 * fa) + vh / (beta_h * fa)
            cb = vb_ / (beta0 * fb_) + vh / (beta_h * fb_)
            pa_n = pa + h * (qva - qdisp_a - lk_a) / (ca - h * (dqva - dlk_a))
            pb_n = pb + h * (qvb - qdisp_b - lk_b) / (cb - h * (dqvb - dlk_b))
            ua_n = pa_n
            ub_n = pb_n
        dua = ua_n - ua
        dub = ub_n - ub
        # effective (linearised) edge flows actually applied this substep
        q_pa_e = q_pa + dq_pa * dua
        q_at_e = q_at + dq_at * dua
        q_pb_e = q_pb + dq_pb * dub
        q_bt_e = q_bt + dq_bt * dub
        if energy:
            uam = 0.5 * (ua + ua_n)
            ubm = 0.5 * (ub + ub_n)
            pam = 0.5 * (pa + pa_n)
            pbm = 0.5 * (pb + pb_n)
            dpa = pa_n - pa
            dpb = pb_n - pb
            if ideal_pump:
                XG[XG_E_SUPPLY] += h * p_s * (q_pa_e + q_pb_e)
            if AP[a, AP_KIND] == 0.0:  # moving piston: d(V p^2 / 2 beta)/dt - p (Q - dV/dt) = p^2 dV/dt / (2 beta)
                XG[XG_E_COMPRESS] += h * (pam * pam * qdisp_a / (2.0 * beta0 * fa) + pbm * pbm * qdisp_b / (2.0 * beta0 * fb_))
            XG[XG_E_TANK] += h * p_t * (q_at_e + q_bt_e)
            XG[XG_E_VALVE] += h * (q_pa_e * (p_s - uam) + q_at_e * (uam - p_t) + q_pb_e * (p_s - ubm) + q_bt_e * (ubm - p_t))
            lka_e = lk_a + dlk_a * dpa
            lkb_e = lk_b + dlk_b * dpb
            XG[XG_E_LEAK] += h * (lka_e * (pam - p_t) + lkb_e * (pbm - p_t))
            XG[XG_E_TANK] += h * p_t * (lka_e + lkb_e)
            if AP[a, AP_F_BURST_KV] > 0.0:
                fb, db = orifice(ua - p_t, tr)
                qb_e = AP[a, AP_F_BURST_KV] * (fb + db * dua)
                XG[XG_E_LEAK] += h * qb_e * (uam - p_t)
                XG[XG_E_TANK] += h * p_t * qb_e
        if not line:
            XS[a, XS_QH_A] = q_pa_e - q_at_e
            XS[a, XS_QH_B] = q_pb_e - q_bt_e
        if pa_n < p_min:
            pa_n = p_min
        if pb_n < p_min:
            pb_n = p_min
        if ua_n < p_min:
            ua_n = p_min
        if ub_n < p_min:
            ub_n = p_min
        XS[a, XS_P_A] = pa_n
        XS[a, XS_P_B] = pb_n
        XS[a, XS_PH_A] = ua_n
        XS[a, XS_PH_B] = ub_n
        XS[a, XS_Q_A] = q_pa_e - q_at_e
        XS[a, XS_Q_B] = q_pb_e - q_bt_e
        act[a, T_QS] = q_pa_e + q_pb_e
        q_supply += q_pa + q_pb
        dq_supply -= dq_pa + dq_pb      # d(supply outflow)/d p_s

    # ---- 4. supply node, sensor play, time ---------------------------------------------------------
    if GP[GP_PUMP_QMAX] > 0.0:
        qmax = GP[GP_PUMP_QMAX]
        band = GP[GP_PUMP_BAND]
        pset = GP[GP_P_SUPPLY] * GP[GP_SUPPLY_SAG]
        xr = (pset - p_s) / band       # full flow below p_set - band, none at p_set
        if xr >= 1.0:
            qp, dqp = qmax, 0.0
        elif xr <= 0.0:
            qp, dqp = 0.0, 0.0
        else:
            qp, dqp = qmax * xr, -qmax / band
        qr = 0.0
        dqr = 0.0
        if p_s > GP[GP_SUPPLY_RELIEF_P]:
            qr = GP[GP_SUPPLY_RELIEF_K] * (p_s - GP[GP_SUPPLY_RELIEF_P])
            dqr = GP[GP_SUPPLY_RELIEF_K]
        cs = GP[GP_SUPPLY_C]
        p_s_n = p_s + h * (qp - q_supply - qr) / (cs - h * (dqp - dq_supply - dqr))
        if energy:
            dps = p_s_n - p_s
            psm = 0.5 * (p_s + p_s_n)
            qp_e = qp + dqp * dps
            qr_e = qr + dqr * dps
            XG[XG_E_SUPPLY] += h * qp_e * psm      # energy delivered by the pump
            XG[XG_E_RELIEF_PUMP] += h * qr_e * (psm - p_t)
            XG[XG_E_TANK] += h * p_t * qr_e
        if p_s_n < p_t:
            p_s_n = p_t
        XG[XG_P_S] = p_s_n
    else:
        XG[XG_P_S] = GP[GP_P_SUPPLY] * GP[GP_SUPPLY_SAG]
    for a in range(na):
        if AP[a, AP_E_BACKLASH] != 0.0:
            XS[a, XS_Y_BACK] = play(XS[a, XS_Y_BACK], q[int(AP[a, AP_DOF])], 0.5 * AP[a, AP_BACK_WIDTH])
        else:
            XS[a, XS_Y_BACK] = q[int(AP[a, AP_DOF])]


@njit(inline="always", **_NJ)
def _copy_state(XQ, XS, XG, dq, ds, dg):
    """Copy the state arrays into (dq, ds, dg); no allocation."""
    for i in range(XQ.shape[1]):
        dq[0, i] = XQ[0, i]
        dq[1, i] = XQ[1, i]
    for a in range(XS.shape[0]):
        for c in range(XS.shape[1]):
            ds[a, c] = XS[a, c]
    for c in range(XG.shape[0]):
        dg[c] = XG[c]


@njit(**_NJ)
def _state_ok(XQ, XS, XG):
    for i in range(XQ.shape[1]):
        if not (math.isfinite(XQ[0, i]) and math.isfinite(XQ[1, i])):
            return False
    for a in range(XS.shape[0]):
        for c in range(XS.shape[1]):
            if not math.isfinite(XS[a, c]):
                return False
    return math.isfinite(XG[XG_P_S])


@njit(**_NJ)
def advance(dts, U, tree, DP, AP, GP, XQ, XS, XG, HT, HU, rng, ws, backup, Yt, Yq, Yqd, Ya):
    """Advance ``len(dts)`` output steps with commands ``U[k]`` held over ``dts[k]`` seconds.

    Row ``k`` of the outputs holds the state at the end of step ``k``. Returns the number of steps
    completed; on a non-finite state the last good state is restored and ``XG[XG_ERROR]`` is set.
    """
    n_out = dts.shape[0]
    na = AP.shape[0]
    bq, bs, bg = backup
    cap = HT.shape[0]
    hmax = GP[GP_H_MAX]
    rb_every = int(GP[GP_RB_EVERY])
    Acc, Bcc, expw = ws[25], ws[26], ws[27]
    wsk = ws[:25]
    for k in range(n_out):
        dt = dts[k]
        _copy_state(XQ, XS, XG, bq, bs, bg)
        t = XG[XG_TIME]
        cnt = int(XG[XG_HIST_COUNT])
        slot = cnt % cap
        HT[slot] = t
        for a in range(na):
            u = U[k, a]
            if not math.isfinite(u):
                u = 0.0
            if u < AP[a, AP_U_MIN]:
                u = AP[a, AP_U_MIN]
            elif u > AP[a, AP_U_MAX]:
                u = AP[a, AP_U_MAX]
            HU[slot, a] = u
        XG[XG_HIST_COUNT] = cnt + 1
        nsub = int(math.ceil(dt / hmax - 1e-9))
        if nsub < 1:
            nsub = 1
        h = dt / nsub
        refresh_command_chain(AP, h, Acc, Bcc, expw)
        for s in range(nsub):
            refresh = (s == 0) if rb_every <= 0 else (int(XG[XG_STEPS]) % rb_every == 0)
            _substep(h, t + s * h, HU[slot], tree, DP, AP, GP, XQ, XS, XG, HT, HU, wsk, refresh)
            XG[XG_STEPS] += 1.0
        XG[XG_TIME] = t + dt
        if not _state_ok(XQ, XS, XG):
            _copy_state(bq, bs, bg, XQ, XS, XG)   # roll back to the last good state
            XG[XG_ERROR] = ERR_NAN
            return k
        Yt[k] = XG[XG_TIME]
        for i in range(XQ.shape[1]):
            Yq[k, i] = XQ[0, i]
            Yqd[k, i] = XQ[1, i]
        sample_sensors(AP, XQ[0], XS, rng, Ya[k], HU[slot])
    return n_out
