"""Per-tick I/O of the engine, compiled: commands -> plant input, plant state -> shared snapshot and
recording row. One call each, no allocation, no per-joint Python loop (the Python version of these
cost ~60 us a tick in small numpy temporaries).

The plant's state columns arrive as a runtime index array (:func:`plant_columns`), not as constants
frozen into the compiled code: numba's on-disk cache is keyed on this file, so a change of the
simulator's layout must never run against machine code compiled for the old one.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import atomics as A
from . import shared as S

_NJ = dict(cache=True, nogil=True)

C_VOLT, C_SOURCE, C_T_WALL, C_T_SIM = S.C_VOLT, S.C_SOURCE, S.C_T_WALL, S.C_T_SIM
SRC_CAN = S.SRC_CAN
A_U_REQ, A_U, A_SENS_V, A_ANGLE, A_P_A, A_P_B, A_SPOOL, A_WATCHDOG, A_SOURCE, A_WD_TRIPS = (
    S.A_U_REQ, S.A_U, S.A_SENS_V, S.A_ANGLE, S.A_P_A, S.A_P_B, S.A_SPOOL, S.A_WATCHDOG, S.A_SOURCE, S.A_WD_TRIPS)
S_TICK, S_TIME, S_WALL, S_MODE, S_ESTOP, S_P_SUPPLY, S_ALIVE, S_DIVERGED = (
    S.S_TICK, S.S_TIME, S.S_WALL, S.S_MODE, S.S_ESTOP, S.S_P_SUPPLY, S.S_ALIVE, S.S_DIVERGED)
W_STATE_SEQ, W_REC_ROWS = S.W_STATE_SEQ, S.W_REC_ROWS

# positions in the plant-column index array
K_SENS_V, K_SENS_ANGLE, K_P_A, K_P_B, K_SPOOL_X, K_TIME, K_P_SUPPLY, K_N = range(8)


def plant_columns() -> np.ndarray:
    """The simulator's state columns this module reads, looked up now (sim_core's published layout)."""
    from sim_core.kernel import layout as KL

    cols = np.zeros(K_N, dtype=np.int64)
    cols[K_SENS_V], cols[K_SENS_ANGLE] = KL.XS_SENS_V, KL.XS_SENS_ANGLE
    cols[K_P_A], cols[K_P_B], cols[K_SPOOL_X] = KL.XS_P_A, KL.XS_P_B, KL.XS_SPOOL_X
    cols[K_TIME], cols[K_P_SUPPLY] = KL.XG_TIME, KL.XG_P_S
    return cols


@njit(**_NJ)
def apply_commands(cmd, u, wd, wd_trips, hold_neutral, age_wall, now_wall, t_sim, watchdog_s):
    """Plant input ``u`` from the command table: CAN commands older than the watchdog timeout and
    everything while ``hold_neutral`` (E-STOP, diverged plant) go to 0 V. ``age_wall``: 1 measures
    age in wall time (realtime), 0 in simulated time. Counts new trips per joint in ``wd_trips``
    and returns their number."""
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
                    wd_trips[a] += 1.0
        wd[a] = tripped
        if hold_neutral != 0.0:
            v = 0.0
        u[a] = v
    return trips


@njit(**_NJ)
def publish(sync, state, cols, n_dof, XQ, XS, XG, cmd, u, wd, wd_trips, tick, wall, mode, estop, diverged):
    """Write the state snapshot under its seqlock."""
    A.write_begin(sync, W_STATE_SEQ)
    state[S_TICK] = tick
    state[S_TIME] = XG[cols[K_TIME]]
    state[S_WALL] = wall
    state[S_MODE] = mode
    state[S_ESTOP] = estop
    state[S_P_SUPPLY] = XG[cols[K_P_SUPPLY]]
    state[S_ALIVE] = 1.0
    state[S_DIVERGED] = diverged
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
        state[o + A_WD_TRIPS] = wd_trips[a]
        state[o + A_SENS_V] = XS[a, cols[K_SENS_V]]
        state[o + A_ANGLE] = XS[a, cols[K_SENS_ANGLE]]
        state[o + A_P_A] = XS[a, cols[K_P_A]]
        state[o + A_P_B] = XS[a, cols[K_P_B]]
        state[o + A_SPOOL] = XS[a, cols[K_SPOOL_X]]
    A.write_end(sync, W_STATE_SEQ)


@njit(**_NJ)
def record_row(sync, rec, cols, XS, XG, u, sensed_idx, tick):
    """Append one dataset row to the recording ring (time, u per joint, measured angle per sensed
    joint, p_a per joint, p_b per joint, tick), then publish the row count (release)."""
    rows = A.load_relaxed(sync, W_REC_ROWS)
    row = rec[rows % rec.shape[0]]
    na = XS.shape[0]
    ns = sensed_idx.shape[0]
    row[0] = XG[cols[K_TIME]]
    for a in range(na):
        row[1 + a] = u[a]
        row[1 + na + ns + a] = XS[a, cols[K_P_A]]
        row[1 + 2 * na + ns + a] = XS[a, cols[K_P_B]]
    for k in range(ns):
        row[1 + na + k] = XS[sensed_idx[k], cols[K_SENS_ANGLE]]
    row[row.shape[0] - 1] = tick
    A.store_release(sync, W_REC_ROWS, rows + 1)
