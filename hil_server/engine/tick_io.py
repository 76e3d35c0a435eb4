"""Per-tick I/O of the engine, compiled: commands -> plant input, plant state -> shared snapshot and
recording row. One call each, no allocation, no per-joint Python loop (the Python version of these
cost ~60 us a tick in small numpy temporaries)."""

from __future__ import annotations

from numba import njit

from sim_core.kernel import layout as KL

from . import shared as S

_NJ = dict(cache=True, nogil=True)

C_VOLT, C_SOURCE, C_T_WALL, C_T_SIM = S.C_VOLT, S.C_SOURCE, S.C_T_WALL, S.C_T_SIM
SRC_CAN = S.SRC_CAN
A_U_REQ, A_U, A_SENS_V, A_ANGLE, A_P_A, A_P_B, A_SPOOL, A_WATCHDOG, A_SOURCE = (
    S.A_U_REQ, S.A_U, S.A_SENS_V, S.A_ANGLE, S.A_P_A, S.A_P_B, S.A_SPOOL, S.A_WATCHDOG, S.A_SOURCE)
S_SEQ, S_TICK, S_TIME, S_WALL, S_MODE, S_ESTOP, S_P_SUPPLY, S_ALIVE = (
    S.S_SEQ, S.S_TICK, S.S_TIME, S.S_WALL, S.S_MODE, S.S_ESTOP, S.S_P_SUPPLY, S.S_ALIVE)
XS_SENS_V, XS_SENS_ANGLE, XS_P_A, XS_P_B, XS_SPOOL_X = KL.XS_SENS_V, KL.XS_SENS_ANGLE, KL.XS_P_A, KL.XS_P_B, KL.XS_SPOOL_X
XG_TIME, XG_P_S = KL.XG_TIME, KL.XG_P_S


@njit(**_NJ)
def apply_commands(cmd, u, wd, estop, age_wall, now_wall, t_sim, watchdog_s):
    """Plant input ``u`` from the command table: CAN commands older than the watchdog timeout and
    everything under E-STOP go to 0 V. ``age_wall``: 1 measures age in wall time (realtime),
    0 in simulated time. Returns the number of joints whose watchdog newly tripped."""
    trips = 0
    for a in range(cmd.shape[0]):
        v = cmd[a, C_VOLT]
        tripped = 0.0
        if watchdog_s > 0.0 and cmd[a, C_SOURCE] == SRC_CAN:
            age = now_wall - cmd[a, C_T_WALL] if age_wall else t_sim - cmd[a, C_T_SIM]
            if age > watchdog_s:
                tripped = 1.0
                v = 0.0
                if wd[a] == 0.0:
                    trips += 1
        wd[a] = tripped
        if estop != 0.0:
            v = 0.0
        u[a] = v
    return trips


@njit(**_NJ)
def publish(state, n_dof, XQ, XS, XG, cmd, u, wd, tick, wall, mode, estop):
    """Write the state snapshot under its seqlock (state[S_SEQ] odd while writing)."""
    state[S_SEQ] += 1.0
    state[S_TICK] = tick
    state[S_TIME] = XG[XG_TIME]
    state[S_WALL] = wall
    state[S_MODE] = mode
    state[S_ESTOP] = estop
    state[S_P_SUPPLY] = XG[XG_P_S]
    state[S_ALIVE] = 1.0
    hdr = S.S_HDR
    for i in range(n_dof):
        state[hdr + i] = XQ[0, i]
        state[hdr + n_dof + i] = XQ[1, i]
    base = hdr + 2 * n_dof
    na = XS.shape[0]
    for a in range(na):
        o = base + a * S.A_N
        state[o + A_U_REQ] = cmd[a, C_VOLT]
        state[o + A_U] = u[a]
        state[o + A_SOURCE] = cmd[a, C_SOURCE]
        state[o + A_WATCHDOG] = wd[a]
        state[o + A_SENS_V] = XS[a, XS_SENS_V]
        state[o + A_ANGLE] = XS[a, XS_SENS_ANGLE]
        state[o + A_P_A] = XS[a, XS_P_A]
        state[o + A_P_B] = XS[a, XS_P_B]
        state[o + A_SPOOL] = XS[a, XS_SPOOL_X]
    state[S_SEQ] += 1.0


@njit(**_NJ)
def record_row(row, XS, XG, u, sensed_idx, tick):
    """One dataset row: time, u per joint, measured angle per sensed joint, p_a per joint, p_b per joint, tick."""
    na = XS.shape[0]
    ns = sensed_idx.shape[0]
    row[0] = XG[XG_TIME]
    for a in range(na):
        row[1 + a] = u[a]
        row[1 + na + ns + a] = XS[a, XS_P_A]
        row[1 + 2 * na + ns + a] = XS[a, XS_P_B]
    for k in range(ns):
        row[1 + na + k] = XS[sensed_idx[k], XS_SENS_ANGLE]
    row[row.shape[0] - 1] = tick
