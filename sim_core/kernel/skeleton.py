# The compiled plant step: the skeleton that ``kernel.compose`` completes with the composed effect
# phases (the ``fx_*`` functions, inserted at @COMPOSED@) and the actuator dispatch (``act_*``,
# inserted at @ACTUATORS@), then writes to a cache file keyed by the hash of every source it
# inlines. Not imported as it stands.
"""The compiled plant step: one call advances the whole arm by any number of output steps.

Integration scheme per substep ``h`` (chosen for stiff hydraulics, deterministic, no allocation):

1. Command path: the effects' command hooks (delay line, hysteresis, deadband), LabVIEW
   adaptation, amplifiers. The linear chain coil currents -> spool -> lag is advanced *exactly*
   with its zero-order-hold matrix exponential (``components.spool``).
2. Mechanics, symplectic Euler with linearly implicit damping: actuator forces from the old
   pressures, ``(M + h D) dqd = h (tau - bias)``, ``q += h qd_new``. ``M`` and the Coriolis/gravity
   bias are refreshed once per output step (or every ``rb_every`` substeps): joint speeds of
   hydraulic arms are low, so they barely change within a millisecond.
3. Pressures, linearly implicit in each node's own pressure (valve orifice, leakage, relief) with
   the new actuator velocities: ``p += h (Q(p) - Q_disp) / C / (1 - h dQ/dp / C)``; effects may
   replace the hose lumping (``line_dynamics``: T-type lines, node and chamber solved together).
4. Supply node (flow-limited pump), end-of-substep hooks (backlash), time.

This symplectic/implicit split is stable at the orifice stiffness and accurate on the lightly
damped hydro-mechanical modes (research note 'performance-measurements', scheme SIP); the tests
compare it with scipy's Radau.
"""

import math

import numpy as np
from numba import njit

from sim_core.components.amplifier import AMP_GAIN, AMP_IMAX, amplifier_current
from sim_core.components.chambers import P_A, P_B, Q_A, Q_B, chamber_outflows, floor
from sim_core.components.directional_valve import KV, edge_conductances, edge_flows, valve_flows_only
from sim_core.components.fluid import BETA, P_MIN
from sim_core.components.hose import burst_flow, lumped_derivatives, lumped_pressures
from sim_core.components.joint import LOCKED, joint_forces, stop_force
from sim_core.components.labview_adaptation import adapt
from sim_core.components.potentiometer import SENSED, read_sensor
from sim_core.components.pump import P_S, P_TANK, PUMP_QMAX, supply_derivative, supply_node, supply_pressure
from sim_core.components.spool import (
    SPOOL_X, advance_chain, chain_derivative, metering_position, refresh_command_chain, spool_position, stuck_spool,
)
from sim_core.dynamics.rigid_body import crba, kinematics, ltl_factor, ltl_solve, rnea
from sim_core.kernel.borrow import borrow
from sim_core.kernel.layout import (
    AP_DOF, AP_KIND, AP_U_MAX, AP_U_MIN, ERR_NAN, GP_ENERGY, GP_H_MAX, GP_JAC_TOL, GP_RB_EVERY, XG_E_ACT, XG_E_COMPRESS,
    XG_E_LEAK, XG_E_MECH, XG_E_SUPPLY, XG_E_TANK, XG_E_VALVE, XG_ERROR, XG_FACTORS, XG_HIST_COUNT, XG_STEPS, XG_TIME, XS_U_EFF,
    YA_ANGLE, YA_P_A, YA_P_B, YA_Q_A, YA_SENS_V, YA_SPOOL, YA_U,
)

_NJ = dict(cache=True, nogil=True)

# @COMPOSED@

# @ACTUATORS@


@njit(**_NJ)
def rigid_body_refresh(tree, q, qd, ws):
    """M(q) and the Coriolis/gravity bias at the current state."""
    _rigid_body_refresh(tree, q, qd, ws, tree.jtype)


@njit(**_NJ)
def _rigid_body_refresh(tree, q, qd, ws, jtype):
    # ``jtype`` is None for an all-revolute tree: numba prunes the branch on the argument's type, so
    # such a tree runs the revolute-only code
    if jtype is None:
        kinematics(tree.parent, tree.R_tree, tree.p_tree, tree.axis, tree.com, tree.inertia, q,
                   ws.Rw, ws.ow, ws.aw, ws.cw, ws.Iw, ws.tmp33)
        crba(tree.parent, tree.mass, ws.ow, ws.aw, ws.cw, ws.Iw, ws.mc, ws.hc, ws.Ic, ws.M)
        rnea(tree.parent, tree.mass, tree.gravity, ws.ow, ws.aw, ws.cw, ws.Iw, qd, ws.zero, 1.0,
             ws.w, ws.dw, ws.ao, ws.F, ws.N, ws.bias)
    else:
        kinematics(tree.parent, tree.R_tree, tree.p_tree, tree.axis, tree.com, tree.inertia, q,
                   ws.Rw, ws.ow, ws.aw, ws.cw, ws.Iw, ws.tmp33, jtype)
        crba(tree.parent, tree.mass, ws.ow, ws.aw, ws.cw, ws.Iw, ws.mc, ws.hc, ws.Ic, ws.M, jtype)
        rnea(tree.parent, tree.mass, tree.gravity, ws.ow, ws.aw, ws.cw, ws.Iw, qd, ws.zero, 1.0,
             ws.w, ws.dw, ws.ao, ws.F, ws.N, ws.bias, jtype)


@njit(**_NJ)
def prime_actuators(DP, AP, XQ, XS):
    """Per-actuator quantities cached in the state (cylinder length and moment arm) at the current
    positions; called at the start of every advance, as the state may have been set from outside."""
    for a in range(AP.shape[0]):
        dof = int(AP[a, AP_DOF])
        th, om = fx_actuator_motion(a, dof, XQ[0], XQ[1], AP, XS)
        act_prime(a, th, AP, XS)


@njit(inline="always")
def substep(h, t, u_in, tree, DP, AP, GP, XQ, XS, XG, HT, HU, ws, refresh_rb, refactor):
    n = tree.parent.shape[0]
    na = AP.shape[0]
    q = XQ[0]
    qd = XQ[1]
    energy = GP[GP_ENERGY] != 0.0
    p_t = GP[P_TANK]
    beta0 = GP[BETA]
    p_min = GP[P_MIN]
    p_s = XG[P_S]
    rhs = ws.rhs
    Dlin = ws.Dlin
    Ffr = ws.Ffr
    Sfr = ws.Sfr
    Tact = ws.Tact
    Kst = ws.Kst
    Lf = ws.Lf
    spool_s = ws.spool_s

    if refresh_rb:
        rigid_body_refresh(tree, q, qd, ws)

    # ---- 1. command path ---------------------------------------------------------------------
    for a in range(na):
        if DP[int(AP[a, AP_DOF]), LOCKED] != 0.0:
            spool_s[a] = 0.0
            continue
        u = fx_command(u_in[a], a, t, h, AP, XS, XG, HT, HU)
        XS[a, XS_U_EFF] = u
        va, vb = adapt(u)
        ira = amplifier_current(va, AP[a, AMP_GAIN], AP[a, AMP_IMAX])
        irb = amplifier_current(vb, AP[a, AMP_GAIN], AP[a, AMP_IMAX])
        x_old = fx_metering(a, AP, XS)
        advance_chain(a, ira, irb, AP, XS)
        x_old = stuck_spool(a, x_old, AP, XS)
        spool_s[a] = metering_position(a, x_old, fx_metering(a, AP, XS), AP)

    # ---- 2. mechanics ------------------------------------------------------------------------
    # F(qd) = -bias + tau_act - D qd + stops + friction; (M + h dF/dqd) dqd = h F(qd_old)
    for i in range(n):
        damp, stop, dlin, kst = joint_forces(i, q[i], qd[i], DP)
        rhs[i] = -ws.bias[i] + damp
        rhs[i] += stop
        Dlin[i] = dlin
        Kst[i] = kst
        Ffr[i] = 0.0
        Sfr[i] = 0.0
        Tact[i] = 0.0
    for a in range(na):
        dof = int(AP[a, AP_DOF])
        if DP[dof, LOCKED] != 0.0:
            continue
        tau_h, visc = act_force(a, AP, XS)
        f, dl, work = fx_coupling(a, dof, h, tau_h, visc, q, qd, AP, XS, XG, energy)
        rhs[dof] += f
        Dlin[dof] += dl
        Tact[dof] += work
        tf, slope = fx_joint_friction(a, qd[dof], AP)
        rhs[dof] += tf
        Ffr[dof] += tf
        Sfr[dof] += slope
    # M only changes at a refresh; the implicit damping on its diagonal (seal friction through the
    # moment arm, friction slopes, end-stop contact) every substep. Between refreshes the factor is
    # kept while each diagonal term stays within GP_JAC_TOL of the one it was factored with (a
    # W-method: the update stays consistent, and the energy ledger books the difference).
    Dfac = ws.Dfac
    Dnew = ws.Dnew
    tol = GP[GP_JAC_TOL]
    for i in range(n):
        Dnew[i] = h * (Dlin[i] - Sfr[i]) + h * h * Kst[i]   # stop spring implicit: q_new = q + h qd_new
        if abs(Dnew[i] - Dfac[i]) > tol * (ws.M[i, i] + abs(Dfac[i])):
            refactor = True
    if refactor:
        for i in range(n):
            for j in range(n):
                Lf[i, j] = ws.M[i, j]
            Lf[i, i] += Dnew[i]
            Dfac[i] = Dnew[i]
    for i in range(n):
        if DP[i, LOCKED] != 0.0:  # held rigid: qdd = 0, the free joints see the reduced dynamics
            if refactor:
                for j in range(n):
                    Lf[i, j] = 0.0
                    Lf[j, i] = 0.0
                Lf[i, i] = 1.0
            rhs[i] = 0.0
            qd[i] = 0.0
    if refactor:
        ltl_factor(tree.parent, Lf)
        XG[XG_FACTORS] += 1.0
    ltl_solve(tree.parent, Lf, rhs)  # rhs now holds qdd
    if energy:
        for i in range(n):
            ws.qd0[i] = qd[i]
    for i in range(n):
        qd_new = qd[i] + h * rhs[i]
        if energy:
            # dissipated power of the linearly implicit terms, at the mean velocity of the step
            vavg = 0.5 * (qd[i] + qd_new)
            XG[XG_E_MECH] += h * (Dlin[i] * qd_new - Ffr[i] - Sfr[i] * (qd_new - qd[i])
                                  + (Dfac[i] - Dnew[i]) / h * (qd_new - qd[i])) * vavg
            XG[XG_E_ACT] += h * Tact[i] * vavg
        qd[i] = qd_new
        q[i] += h * qd_new
    if energy:
        for a in range(na):
            dof = int(AP[a, AP_DOF])
            if DP[dof, LOCKED] == 0.0:
                fx_after_mechanics(a, dof, h, q, qd, ws.qd0, AP, XS, XG)

    # ---- 3. pressures -------------------------------------------------------------------------
    q_supply = 0.0
    dq_supply = 0.0
    ideal_pump = GP[PUMP_QMAX] <= 0.0
    for a in range(na):
        dof = int(AP[a, AP_DOF])
        if DP[dof, LOCKED] != 0.0:
            continue
        th, om = fx_actuator_motion(a, dof, q, qd, AP, XS)
        va_, vb_, qdisp_a, qdisp_b, dva, dvb = act_geometry(a, th, om, AP, XS)
        if va_ < 1e-9:
            va_ = 1e-9
        if vb_ < 1e-9:
            vb_ = 1e-9
        pa = XS[a, P_A]
        pb = XS[a, P_B]
        ua, ub = fx_port_pressures(a, pa, pb, AP, XS)
        # --- valve edges
        g_pa, g_pb = edge_conductances(a, spool_s[a], fx_negative_gain(AP[a, KV], a, AP), AP)
        q_pa, q_at, q_pb, q_bt, dq_pa, dq_at, dq_pb, dq_bt = edge_flows(a, g_pa, g_pb, p_s, p_t, ua, ub, AP)
        q_pa, dq_pa, q_pb, dq_pb = fx_edge_limit(q_pa, dq_pa, q_pb, dq_pb, a, AP)
        qva = q_pa - q_at             # into line A
        qvb = q_pb - q_bt
        dqva = dq_pa - dq_at          # <= 0
        dqvb = dq_pb - dq_bt
        qb, dqb = burst_flow(a, ua, p_t, AP)   # hose burst (fault): line A to tank
        qva -= qb
        dqva -= dqb
        # --- chamber outflows: fault leaks and port reliefs, then the effects' leakage
        lk_a, lk_b, dlk_a, dlk_b = chamber_outflows(a, pa, pb, p_t, AP)
        ek_a, ek_b, edk_a, edk_b = fx_leakage(pa, pb, p_t, a, AP)
        lk_a += ek_a
        lk_b += ek_b
        dlk_a += edk_a
        dlk_b += edk_b
        pa_n, pb_n, ua_n, ub_n, fa, fb = fx_pressures(
            a, h, ua, ub, pa, pb, qva, dqva, qvb, dqvb, va_, vb_, qdisp_a, qdisp_b,
            lk_a, dlk_a, lk_b, dlk_b, beta0, fx_bulk, GP, AP, XS, XG, energy)
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
            # a moving piston: d(V G(p) / beta)/dt - p (Q - dV/dt) = G(p) dV/dt / beta  (G = p^2/2 for constant beta)
            XG[XG_E_COMPRESS] += h * (fx_compression_energy(pam, GP) * dva + fx_compression_energy(pbm, GP) * dvb) / beta0
            XG[XG_E_TANK] += h * p_t * (q_at_e + q_bt_e)
            XG[XG_E_VALVE] += h * (q_pa_e * (p_s - uam) + q_at_e * (uam - p_t) + q_pb_e * (p_s - ubm) + q_bt_e * (ubm - p_t))
            lka_e = lk_a + dlk_a * dpa
            lkb_e = lk_b + dlk_b * dpb
            XG[XG_E_LEAK] += h * (lka_e * (pam - p_t) + lkb_e * (pbm - p_t))
            XG[XG_E_TANK] += h * p_t * (lka_e + lkb_e)
            qb_e = qb + dqb * dua
            XG[XG_E_LEAK] += h * qb_e * (uam - p_t)
            XG[XG_E_TANK] += h * p_t * qb_e
        pa_n = floor(pa_n, p_min)
        pb_n = floor(pb_n, p_min)
        ua_n = floor(ua_n, p_min)
        ub_n = floor(ub_n, p_min)
        XS[a, P_A] = pa_n
        XS[a, P_B] = pb_n
        XS[a, Q_A] = q_pa_e - q_at_e
        XS[a, Q_B] = q_pb_e - q_bt_e
        fx_after_pressures(a, ua_n, ub_n, q_pa_e - q_at_e, q_pb_e - q_bt_e, AP, XS)
        q_supply += q_pa + q_pb
        dq_supply -= dq_pa + dq_pb      # d(supply outflow)/d p_s

    # ---- 4. supply node, end of substep --------------------------------------------------------
    supply_node(h, q_supply, dq_supply, GP, XG, energy)
    for a in range(na):
        fx_after_substep(a, q[int(AP[a, AP_DOF])], AP, XS)


@njit(**_NJ)
def sample_sensors(AP, q, XS, rng, Ya_row, u_row):
    """Read every joint sensor like the cFP analog inputs do and fill one output row."""
    for a in range(AP.shape[0]):
        Ya_row[a, YA_U] = u_row[a]
        Ya_row[a, YA_P_A] = XS[a, P_A]
        Ya_row[a, YA_P_B] = XS[a, P_B]
        Ya_row[a, YA_SPOOL] = XS[a, SPOOL_X]
        Ya_row[a, YA_Q_A] = XS[a, Q_A]
        if AP[a, SENSED] == 0.0:
            Ya_row[a, YA_SENS_V] = math.nan
            Ya_row[a, YA_ANGLE] = math.nan
            continue
        q_dof = q[int(AP[a, AP_DOF])]
        v, pos = read_sensor(a, fx_sensor_position(q_dof, a, q_dof, AP, XS), AP, XS, rng)
        Ya_row[a, YA_SENS_V] = v
        Ya_row[a, YA_ANGLE] = pos


@njit(inline="always")
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
    return math.isfinite(XG[P_S])


@njit(**_NJ)
def advance(dts, U, tree, DP, AP, GP, XQ, XS, XG, HT, HU, rng, ws, Yt, Yq, Yqd, Ya):
    """Advance ``len(dts)`` output steps with commands ``U[k]`` held over ``dts[k]`` seconds.

    Row ``k`` of the outputs holds the state at the end of step ``k``. Returns the number of steps
    completed; on a non-finite state the last good state is restored and ``XG[XG_ERROR]`` is set.
    """
    # unowned views: no reference counting in the loop (the caller holds the arrays for the call)
    dts, U, tree, DP, AP, GP, XQ, XS, XG, HT, HU = borrow((dts, U, tree, DP, AP, GP, XQ, XS, XG, HT, HU))
    rng, ws, Yt, Yq, Yqd, Ya = borrow((rng, ws, Yt, Yq, Yqd, Ya))
    n_out = dts.shape[0]
    na = AP.shape[0]
    cap = HT.shape[0]
    hmax = GP[GP_H_MAX]
    rb_every = int(GP[GP_RB_EVERY])
    prime_actuators(DP, AP, XQ, XS)
    for k in range(n_out):
        dt = dts[k]
        _copy_state(XQ, XS, XG, ws.bq, ws.bs, ws.bg)
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
        refresh_command_chain(AP, h, ws.Acc, ws.Bcc, ws.expw)
        for s in range(nsub):
            refresh = (s == 0) if rb_every <= 0 else (int(XG[XG_STEPS]) % rb_every == 0)
            # a factor the simulator marked stale (new parameters: locks) is renewed by the tolerance
            # test (workspace.STALE), so a call continues another with the bits of one run
            substep(h, t + s * h, HU[slot], tree, DP, AP, GP, XQ, XS, XG, HT, HU, ws, refresh, refresh)
            XG[XG_STEPS] += 1.0
        XG[XG_TIME] = t + dt
        if not _state_ok(XQ, XS, XG):
            _copy_state(ws.bq, ws.bs, ws.bg, XQ, XS, XG)   # roll back to the last good state
            XG[XG_ERROR] = ERR_NAN
            return k
        Yt[k] = XG[XG_TIME]
        for i in range(XQ.shape[1]):
            Yq[k, i] = XQ[0, i]
            Yqd[k, i] = XQ[1, i]
        sample_sensors(AP, XQ[0], XS, rng, Ya[k], HU[slot])
    return n_out


# ---- the same equations in continuous time, for the reference solver ------------------------------
@njit(**_NJ)
def derivatives(ueff, tree, DP, AP, GP, XQ, XS, p_s_state, ws, dXQ, dXS):
    """dX/dt of the plant at state (XQ, XS, supply pressure) with the effective commands ``ueff``
    (after the command-path effects, applied exactly by the reference solver). Returns dp_s/dt."""
    ueff, tree, DP, AP, GP, XQ, XS, ws, dXQ, dXS = borrow((ueff, tree, DP, AP, GP, XQ, XS, ws, dXQ, dXS))
    n = tree.parent.shape[0]
    na = AP.shape[0]
    q = XQ[0]
    qd = XQ[1]
    tau = ws.rhs
    rigid_body_refresh(tree, q, qd, ws)
    for i in range(n):
        damp, stop, dlin, kst = joint_forces(i, q[i], qd[i], DP)
        tau[i] = -ws.bias[i] + damp
        tau[i] += stop_force(i, q[i], qd[i], DP)
    p_s = supply_pressure(p_s_state, GP)
    p_t = GP[P_TANK]
    beta0 = GP[BETA]
    q_supply = 0.0
    for a in range(na):
        for c in range(dXS.shape[1]):
            dXS[a, c] = 0.0
        dof = int(AP[a, AP_DOF])
        va, vb = adapt(ueff[a])
        ira = amplifier_current(va, AP[a, AMP_GAIN], AP[a, AMP_IMAX])
        irb = amplifier_current(vb, AP[a, AMP_GAIN], AP[a, AMP_IMAX])
        chain_derivative(a, ira, irb, AP, XS, dXS)
        s = fx_metering(a, AP, XS)
        s = metering_position(a, s, s, AP)
        th, om = fx_actuator_motion(a, dof, q, qd, AP, XS)
        va_, vb_, qdisp_a, qdisp_b, dva, dvb = act_geometry(a, th, om, AP, XS)
        tau_h, visc = act_force(a, AP, XS)
        tau[dof] += fx_reference_coupling(a, dof, tau_h, visc, q, qd, AP, XS, dXS)
        tf, slope = fx_joint_friction(a, qd[dof], AP)
        tau[dof] += tf
        pa = XS[a, P_A]
        pb = XS[a, P_B]
        ua, ub = fx_port_pressures(a, pa, pb, AP, XS)
        g_pa, g_pb = edge_conductances(a, s, fx_negative_gain(AP[a, KV], a, AP), AP)
        q_pa, q_at, q_pb, q_bt = valve_flows_only(a, g_pa, g_pb, p_s, p_t, ua, ub, AP)
        q_pa, _d1, q_pb, _d2 = fx_edge_limit(q_pa, 0.0, q_pb, 0.0, a, AP)
        qva = q_pa - q_at
        qvb = q_pb - q_bt
        qva -= burst_flow(a, ua, p_t, AP)[0]
        q_supply += q_pa + q_pb
        lk_a, lk_b, _l1, _l2 = chamber_outflows(a, pa, pb, p_t, AP)
        ek_a, ek_b, _e1, _e2 = fx_leakage(pa, pb, p_t, a, AP)
        lk_a += ek_a
        lk_b += ek_b
        dpa, dpb = fx_reference_pressures(a, ua, ub, pa, pb, qva, qvb, va_, vb_, qdisp_a, qdisp_b,
                                          lk_a, lk_b, beta0, fx_bulk, GP, AP, XS, dXS)
        # cavitation floor (projected): a chamber at vapour pressure cannot fall further
        dXS[a, P_A] = 0.0 if (pa <= GP[P_MIN] and dpa < 0.0) else dpa
        dXS[a, P_B] = 0.0 if (pb <= GP[P_MIN] and dpb < 0.0) else dpb
    for i in range(n):
        dXQ[0, i] = qd[i]
    ltl_factor(tree.parent, ws.M)
    ltl_solve(tree.parent, ws.M, tau)
    for i in range(n):
        dXQ[1, i] = tau[i]
    return supply_derivative(p_s, q_supply, GP)
