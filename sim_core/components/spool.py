"""Directional-valve spool dynamics and the exact discretisation of the command chain."""

import math

import numpy as np
from numba import njit

from ..kernel.layout import AP, XS, col
from .base import Component, Parameter
from .proportional_solenoid import SOL_TAU

# the linear command chain z = [i_A, i_B, x, x', x_lag]: five contiguous state columns
I_A, I_B, SPOOL_X, SPOOL_V, LAG_X = XS.declare(
    "spool",
    col("I_A", "A", "solenoid A current", ode=True, atol=1e-10),
    col("I_B", "A", "solenoid B current", ode=True, atol=1e-10),
    col("SPOOL_X", "-", "spool position (stroke fraction)", ode=True, atol=1e-10),
    col("SPOOL_V", "1/s", "spool velocity", ode=True, atol=1e-8),
    col("LAG_X", "-", "spool_lag filtered position (follows the spool when the effect is off)", ode=True, atol=1e-10),
)
SPOOL_GAIN, SPOOL_WN, SPOOL_ZETA, SPOOL_LIMIT, LAG_TAU, CMD_H, PHI, GAM, CMD_H0, PHI0, GAM0 = AP.declare(
    "spool",
    col("SPOOL_GAIN", "1/A", "spool position per net solenoid current"),
    col("SPOOL_WN", "rad/s", "spool natural frequency"),
    col("SPOOL_ZETA", "-", "spool damping ratio"),
    col("SPOOL_LIMIT", "-", "spool end stop (stroke fraction)"),
    col("LAG_TAU", "s", "time constant of the lag state (the spool_lag effect's; 10 ms when off)"),
    col("CMD_H", "s", "substep the matrices below were computed for (-1: none)"),
    col("PHI", "-", "exact discretisation of the command chain, e^{A h} (5 x 5, row major)", 25),
    col("GAM", "-", "its input matrix, int_0^h e^{A s} ds B (5 x 2)", 10),
    col("CMD_H0", "s", "base substep: the first one the chain was discretised for (-1: none)"),
    col("PHI0", "-", "e^{A h0} (5 x 5, row major)", 25),
    col("GAM0", "-", "int_0^h0 e^{A s} ds B (5 x 2)", 10),
)
F_SPOOL_STUCK, F_SPOOL_POS = AP.declare(
    "spool",
    col("F_SPOOL_STUCK", "-", "fault: spool frozen (1.0)"),
    col("F_SPOOL_POS", "-", "fault: where it froze (stroke fraction)"),
)


class Spool(Component):
    """Valve spool as a second-order system driven by the net solenoid force.

        x_ref = K_x (i_A - i_B)
        x'' = w_v^2 (x_ref - x) - 2 zeta_v w_v x'
        metering position: clip(x, -x_lim, x_lim)   (stroke fraction, 1 = fully open)

    Proportional directional valves have a 10-30 Hz bandwidth with zeta ~ 0.6-0.9 (Jelali & Kroll
    2003, §3.3; Hopsan's Hydraulic43Valve uses the same second-order spool). The coil currents, the
    spool and the optional ``spool_lag`` filter form a linear system driven by piecewise-constant
    reference currents, so the kernel integrates them exactly with a matrix exponential.
    """

    section = "spool"
    citation = "M. Jelali, A. Kroll, Hydraulic Servo-systems, Springer, 2003, sec. 3.3"
    PARAMETERS = (
        Parameter("natural_frequency", "Hz", "spool natural frequency", None, 0.5, 500.0),
        Parameter("damping_ratio", "-", "spool damping ratio", None, 0.05, 5.0),
        Parameter("gain", "1/A", "spool position (fraction of stroke) per ampere of net solenoid current", None, 0.0, 100.0),
        Parameter("stroke_limit", "-", "spool end stop, fraction of the metering stroke", 1.0, 0.1, 2.0),
    )
    FAULTS = ("spool_stuck",)

    def lower(self, lw, a, spec, js):
        AP_ = lw.AP
        AP_[a, SPOOL_GAIN] = self["gain"]
        AP_[a, SPOOL_WN] = 2.0 * math.pi * self["natural_frequency"]
        AP_[a, SPOOL_ZETA] = self["damping_ratio"]
        AP_[a, SPOOL_LIMIT] = self["stroke_limit"]
        AP_[a, LAG_TAU] = 0.01
        AP_[a, CMD_H] = -1.0
        AP_[a, CMD_H0] = -1.0

    @staticmethod
    def lower_fault(lw, a, kind, mode):
        lw.AP[a, F_SPOOL_STUCK] = 1.0
        lw.AP[a, F_SPOOL_POS] = float(mode.get("position", 0.0))


@njit
def command_chain_matrix(tau_s, wn, zeta, gain, tau_lag, A, B):
    """Continuous-time matrices of z = [i_A, i_B, x, x', x_lag], w = [i_ref_A, i_ref_B]."""
    for r in range(5):
        for c in range(5):
            A[r, c] = 0.0
        B[r, 0] = 0.0
        B[r, 1] = 0.0
    A[0, 0] = -1.0 / tau_s
    A[1, 1] = -1.0 / tau_s
    B[0, 0] = 1.0 / tau_s
    B[1, 1] = 1.0 / tau_s
    A[2, 3] = 1.0
    A[3, 0] = wn * wn * gain
    A[3, 1] = -wn * wn * gain
    A[3, 2] = -wn * wn
    A[3, 3] = -2.0 * zeta * wn
    A[4, 2] = 1.0 / tau_lag
    A[4, 4] = -1.0 / tau_lag


@njit
def expm_augmented(A, B, h, work, out_phi, out_gam):
    """Exact zero-order-hold discretisation: Phi = e^{Ah}, Gam = int_0^h e^{As} ds B.

    Uses the augmented matrix X = [[A, B], [0, 0]] h, balanced by a diagonal similarity in powers of
    two (exact in floating point: the spool's velocity state is ~w_v^2 times larger than its
    position in A, which would otherwise force many squarings), scaled to a norm below 0.5 and
    squared back, with a Taylor series stopped once a term is below 1e-17 (at most 18 terms). A
    short ``h`` costs a few terms only. ``work`` is [5, 7, 7] (or larger); no allocation.
    """
    n = 7
    X = work[0]
    T = work[1]
    S = work[2]
    P = work[3]
    for r in range(n):
        for c in range(n):
            X[r, c] = 0.0
    for r in range(5):
        for c in range(5):
            X[r, c] = A[r, c] * h
        X[r, 5] = B[r, 0] * h
        X[r, 6] = B[r, 1] * h
    # balance: D X D^-1 with d_i powers of two (Parlett-Reinsch sweeps on the 5 x 5 block)
    d = work[4, 0]
    for i in range(n):
        d[i] = 1.0
    for _ in range(4):
        changed = False
        for i in range(5):
            rsum = 0.0
            csum = 0.0
            for k in range(5):
                if k != i:
                    rsum += abs(X[i, k])
                    csum += abs(X[k, i])
            if rsum == 0.0 or csum == 0.0:
                continue
            f = 1.0
            while csum < 0.5 * rsum:
                csum *= 2.0
                rsum *= 0.5
                f *= 2.0
            while csum > 2.0 * rsum:
                csum *= 0.5
                rsum *= 2.0
                f *= 0.5
            if f != 1.0:
                changed = True
                d[i] *= f
                for k in range(n):
                    X[i, k] /= f     # row i of D X D^-1 scales by 1/f, column i by f
                for k in range(5):
                    X[k, i] *= f
        if not changed:
            break
    nrm = 0.0
    for r in range(n):
        row = 0.0
        for c in range(n):
            row += abs(X[r, c])
        if row > nrm:
            nrm = row
    s = 0
    while nrm > 0.5:
        nrm *= 0.5
        s += 1
    scale = 0.5 ** s
    for r in range(n):
        for c in range(n):
            X[r, c] *= scale
            S[r, c] = 1.0 if r == c else 0.0
            T[r, c] = S[r, c]
    for k in range(1, 19):
        # T = T @ X / k (rows 5, 6 of T stay zero after the first term)
        big = 0.0
        for r in range(5 if k > 1 else n):
            for c in range(n):
                acc = 0.0
                for m in range(5):          # rows 5, 6 of X are zero
                    acc += T[r, m] * X[m, c]
                P[r, c] = acc / k
                if abs(P[r, c]) > big:
                    big = abs(P[r, c])
        for r in range(5 if k > 1 else n):
            for c in range(n):
                T[r, c] = P[r, c]
                S[r, c] += P[r, c]
        if k > 1:
            for r in range(5, n):
                for c in range(n):
                    T[r, c] = 0.0
        if big < 1e-17:
            break
    for _ in range(s):
        for r in range(n):
            for c in range(n):
                acc = 0.0
                for m in range(n):
                    acc += S[r, m] * S[m, c]
                P[r, c] = acc
        for r in range(n):
            for c in range(n):
                S[r, c] = P[r, c]
    # undo the balance: e^X = D^-1 e^{D X D^-1} D
    for r in range(5):
        for c in range(5):
            out_phi[r * 5 + c] = S[r, c] * d[r] / d[c]
        out_gam[r * 2] = S[r, 5] * d[r]
        out_gam[r * 2 + 1] = S[r, 6] * d[r]


@njit
def refresh_command_chain(AP, h, Acc, Bcc, expw):
    """The exact discretisation of every actuator's command chain for substep ``h``.

    The first substep seen becomes the base h0 (its Phi0, Gam0 kept); another h is reached from it
    as Phi(h) = Phi0 e^{A d}, Gam(h) = Gam0 + Phi0 Gam(d) with d = h - h0 (exact: the semigroup
    property), where the short (or negative) d needs a few Taylor terms only. A jittered time grid,
    whose substep changes at every output step, thus costs about as much as a regular one.
    Actuators with the same chain (one valve type on every joint) share one discretisation: an
    actuator whose parameters equal an earlier one's takes that one's matrices. ``expw`` is
    [6, 7, 7] scratch.
    """
    for a in range(AP.shape[0]):
        if abs(AP[a, CMD_H] - h) <= 1e-9 * h:  # grids from arange differ in the last bits
            continue
        twin = -1
        for b in range(a):
            if (AP[b, SOL_TAU] == AP[a, SOL_TAU] and AP[b, SPOOL_WN] == AP[a, SPOOL_WN]
                    and AP[b, SPOOL_ZETA] == AP[a, SPOOL_ZETA] and AP[b, SPOOL_GAIN] == AP[a, SPOOL_GAIN]
                    and AP[b, LAG_TAU] == AP[a, LAG_TAU]):
                twin = b     # already brought to this h above
                break
        if twin >= 0:
            for c in range(CMD_H, GAM0 + 10):
                AP[a, c] = AP[twin, c]
            continue
        command_chain_matrix(AP[a, SOL_TAU], AP[a, SPOOL_WN], AP[a, SPOOL_ZETA],
                             AP[a, SPOOL_GAIN], AP[a, LAG_TAU], Acc, Bcc)
        h0 = AP[a, CMD_H0]
        if h0 <= 0.0 or abs(h - h0) > 0.5 * h0:
            expm_augmented(Acc, Bcc, h, expw, AP[a, PHI:PHI + 25], AP[a, GAM:GAM + 10])
            if h0 <= 0.0:
                AP[a, CMD_H0] = h
                for i in range(25):
                    AP[a, PHI0 + i] = AP[a, PHI + i]
                for i in range(10):
                    AP[a, GAM0 + i] = AP[a, GAM + i]
        else:
            flat = expw[5].reshape(49)      # scratch beyond what expm_augmented uses
            pd = flat[0:25]
            gd = flat[25:35]
            expm_augmented(Acc, Bcc, h - h0, expw, pd, gd)
            for r in range(5):
                for c in range(5):
                    acc = 0.0
                    for m in range(5):
                        acc += AP[a, PHI0 + 5 * r + m] * pd[5 * m + c]
                    AP[a, PHI + 5 * r + c] = acc
                for c in range(2):
                    acc = AP[a, GAM0 + 2 * r + c]
                    for m in range(5):
                        acc += AP[a, PHI0 + 5 * r + m] * gd[2 * m + c]
                    AP[a, GAM + 2 * r + c] = acc
        AP[a, CMD_H] = h


@njit(inline="always")
def advance_chain(a, ira, irb, AP, XS):
    """z <- Phi z + Gam [i_ref_A, i_ref_B]: the chain over one substep, exact for constant currents."""
    z0 = XS[a, I_A]
    z1 = XS[a, I_B]
    z2 = XS[a, SPOOL_X]
    z3 = XS[a, SPOOL_V]
    z4 = XS[a, LAG_X]
    for r in range(5):
        b = PHI + 5 * r
        XS[a, I_A + r] = (AP[a, b] * z0 + AP[a, b + 1] * z1 + AP[a, b + 2] * z2 + AP[a, b + 3] * z3
                          + AP[a, b + 4] * z4 + AP[a, GAM + 2 * r] * ira + AP[a, GAM + 2 * r + 1] * irb)


@njit(inline="always")
def stuck_spool(a, x_old, AP, XS):
    """Fault 'spool_stuck': the chain's spool states frozen at the fault position; the metering
    position of the substep's start then is that position too."""
    if AP[a, F_SPOOL_STUCK] != 0.0:
        XS[a, SPOOL_X] = AP[a, F_SPOOL_POS]
        XS[a, SPOOL_V] = 0.0
        XS[a, LAG_X] = AP[a, F_SPOOL_POS]
        return AP[a, F_SPOOL_POS]
    return x_old


@njit(inline="always")
def metering_position(a, x_old, x_new, AP):
    """Metering position over the substep: the mean of its ends, within the spool's end stops."""
    s = 0.5 * (x_old + x_new)
    lim = AP[a, SPOOL_LIMIT]
    if s > lim:
        s = lim
    elif s < -lim:
        s = -lim
    return s


@njit(inline="always")
def spool_position(a, AP, XS):
    """The position the valve meters with when no effect changes it."""
    return XS[a, SPOOL_X]


@njit(inline="always")
def chain_derivative(a, ira, irb, AP, XS, dXS):
    """Continuous-time chain for the reference solver (the same matrices, not discretised)."""
    ts = AP[a, SOL_TAU]
    wn = AP[a, SPOOL_WN]
    dXS[a, I_A] = (ira - XS[a, I_A]) / ts
    dXS[a, I_B] = (irb - XS[a, I_B]) / ts
    dXS[a, SPOOL_X] = XS[a, SPOOL_V]
    dXS[a, SPOOL_V] = wn * wn * (AP[a, SPOOL_GAIN] * (XS[a, I_A] - XS[a, I_B]) - XS[a, SPOOL_X]) - 2.0 * AP[a, SPOOL_ZETA] * wn * XS[a, SPOOL_V]
    dXS[a, LAG_X] = (XS[a, SPOOL_X] - XS[a, LAG_X]) / AP[a, LAG_TAU]
    if AP[a, F_SPOOL_STUCK] != 0.0:
        dXS[a, SPOOL_X] = 0.0
        dXS[a, SPOOL_V] = 0.0
        dXS[a, LAG_X] = 0.0


def discretise(tau_s: float, wn: float, zeta: float, gain: float, tau_lag: float, h: float):
    """Python helper (tests, reference): (Phi[5,5], Gam[5,2]) for substep ``h``."""
    A = np.zeros((5, 5))
    B = np.zeros((5, 2))
    command_chain_matrix(tau_s, wn, zeta, gain, tau_lag, A, B)
    phi = np.zeros(25)
    gam = np.zeros(10)
    expm_augmented(A, B, h, np.zeros((6, 7, 7)), phi, gam)
    return phi.reshape(5, 5), gam.reshape(5, 2)
