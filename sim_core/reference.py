"""Reference solution of the same model with a variable-step stiff solver (scipy Radau/LSODA).

The plant's continuous-time equations ``dy/dt = f(t, y)`` come from the same component and effect
functions as the fixed-step kernel (the composed kernel's ``derivatives``), integrated here by a
different method. The state vector is assembled from the declared layout: the joint positions and
velocities, every actuator's continuous states (the ``XS`` columns declared ``ode=True``, with their
tolerances) and the supply pressure. With the command piecewise constant (delay, hysteresis and
deadband applied exactly at the switching instants by the effects' ``reference_command``) each
constant piece is integrated to tight tolerance. The tests compare the kernel against it;
``hydrohil bench`` reports the speed ratio.

The cavitation floor is a projection (dp/dt clipped at vapour pressure) where the kernel clamps;
sensor models are not applied (the reference returns true states).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import Radau, solve_ivp
from scipy.integrate._ivp.common import num_jac

from .components.pump import P_S
from .effects import EFFECTS
from .kernel import layout as L
from .kernel.compose import kernel
from .kernel.workspace import make_workspace, tree_arrays


def ode_columns() -> list[L.Column]:
    """The actuator state columns the reference solver integrates, in layout order."""
    L._load_owners()
    return [c for c in L.XS.columns if c.ode]


def _command_effects(ctx, a: int) -> list:
    return [e for e in sorted(EFFECTS.values(), key=lambda e: e.ORDER)
            if "command" in e.HOOKS and ctx.effect_on(e, a)]


def _effective_commands(ctx, times, U):
    """Exact piecewise-constant effective command (after the command-path effects) per actuator.

    Returns (breakpoints [M+1], values [M, n_act]) covering [times[0], times[-1]]."""
    AP = ctx.AP
    na = AP.shape[0]
    t0, t_end = times[0], times[-1]
    delays = [sum(e.command_delay(AP, a) for e in _command_effects(ctx, a)) for a in range(na)]
    bps = {t0, t_end}
    for a in range(na):
        for t in times[:-1]:
            if t0 < t + delays[a] < t_end:
                bps.add(t + delays[a])
    bps = np.array(sorted(bps))
    mids = 0.5 * (bps[:-1] + bps[1:])
    vals = np.zeros((mids.size, na))
    for a in range(na):
        d = delays[a]
        lo, hi = AP[a, L.AP_U_MIN], AP[a, L.AP_U_MAX]
        effects = _command_effects(ctx, a)
        memory: dict = {}
        for m, tm in enumerate(mids):
            k = np.searchsorted(times, tm - d, side="right") - 1
            u = 0.0 if k < 0 else float(np.clip(U[k, a], lo, hi))
            for e in effects:
                u = e.reference_command(u, a, AP, ctx.XS, memory)
            vals[m, a] = u
    return bps, vals


def initial_vector(ctx) -> np.ndarray:
    n, na = ctx.spec.tree.n, len(ctx.spec.joints)
    idx = [c.index for c in ode_columns()]
    return np.concatenate([ctx.XQ[0], ctx.XQ[1], ctx.XS[:, idx].ravel(), [ctx.XG[P_S]]])


def solve_reference(ctx, times, U, *, method: str = "Radau", rtol: float = 1e-8, max_step: float = np.inf):
    """Integrate the context's model from its current state on ``times`` with commands ``U`` (ZOH).

    Returns (q [N, n_dof] true positions, y [N, n_states])."""
    times = np.asarray(times, dtype=float)
    U = np.asarray(U, dtype=float)
    K = kernel()
    lw = ctx.lowered
    tree = tree_arrays(ctx.spec.tree, lw)
    n, na = ctx.spec.tree.n, len(ctx.spec.joints)
    cols = ode_columns()
    idx = np.array([c.index for c in cols])
    m = idx.size
    ws = make_workspace(n, na)
    K.prime_actuators(ctx.DP, ctx.AP, ctx.XQ, ctx.XS)
    XQw = np.zeros((2, n))
    XSw = ctx.XS.copy()
    dXQ = np.zeros((2, n))
    dXS = np.zeros_like(XSw)
    y = initial_vector(ctx)
    atol = np.concatenate([np.full(n, 1e-10), np.full(n, 1e-9), np.tile([c.atol for c in cols], na), [1e-2]])
    bps, vals = _effective_commands(ctx, times, U)
    out = np.zeros((times.size, y.size))
    out[0] = y
    dy = np.zeros_like(y)

    def f(_t, yy, ueff):
        XQw[0] = yy[:n]
        XQw[1] = yy[n:2 * n]
        XSw[:, idx] = yy[2 * n:2 * n + na * m].reshape(na, m)
        dps = K.derivatives(ueff, tree, ctx.DP, ctx.AP, ctx.GP, XQw, XSw, yy[-1], ws, dXQ, dXS)
        dy[:n] = dXQ[0]
        dy[n:2 * n] = dXQ[1]
        dy[2 * n:2 * n + na * m] = dXS[:, idx].ravel()
        dy[-1] = dps
        return dy.copy()

    carried = _Carried()
    for k in range(bps.size - 1):
        ta, tb = bps[k], bps[k + 1]
        sel = np.flatnonzero((times > ta) & (times <= tb))
        ueff = vals[k].copy()
        if method == "Radau":
            ys = _radau_piece(f, ta, tb, y, ueff, times[sel], rtol, atol, max_step, carried)
        else:
            t_eval = np.append(times[sel][times[sel] < tb], tb)
            sol = solve_ivp(f, (ta, tb), y, method=method, rtol=rtol, atol=atol, t_eval=t_eval, args=(ueff,),
                            max_step=max_step)
            if not sol.success:
                raise RuntimeError(f"reference solver failed at t = {ta:.4f}: {sol.message}")
            ys = sol.y.T        # the samples in (ta, tb], then tb (the same row when the last sample is tb)
        if sel.size:
            out[sel] = ys[:sel.size]
        y = ys[-1]
    return out[:, :n], out


class _Carried:
    """What one constant piece's Radau hands the next: its last step size (s) and Jacobian."""

    def __init__(self):
        self.h: float | None = None
        self.J: np.ndarray | None = None


def _radau_piece(f, ta, tb, y, ueff, t_out, rtol, atol, max_step, carried: _Carried) -> np.ndarray:
    """Radau over one constant piece [ta, tb]: the states at ``t_out`` (the record's samples in
    (ta, tb]) and, last, at ``tb``.

    The command jumps at every breakpoint, so each piece is a new initial value problem, but a fresh
    solver would start from a tiny step and differentiate the model anew: on 1 ms pieces that was
    most of the reference's cost. Here the solver starts with the previous piece's last step size and
    Jacobian; the Jacobian is only Radau's Newton matrix (accuracy is set by its error estimate,
    unchanged), and when Newton converges slowly Radau asks for a fresh one, differentiated here as
    scipy does by default."""
    def fun(t, yy):
        return f(t, yy, ueff)

    def fun_vectorized(t, Y):
        return np.stack([fun(t, Y[:, i]) for i in range(Y.shape[1])], axis=1)

    reuse = carried.J is not None

    def jac(t, yy):
        nonlocal reuse
        if reuse:                   # the constructor's request: the last piece's Jacobian
            reuse = False
            return carried.J
        carried.J, _ = num_jac(fun_vectorized, t, yy, fun(t, yy), atol, None)
        return carried.J

    span = tb - ta
    h0 = None if carried.h is None else min(carried.h, span, max_step)
    solver = Radau(fun, ta, y, tb, rtol=rtol, atol=atol, max_step=max_step, first_step=h0, jac=jac)
    ys = []
    i = 0
    while solver.status == "running":
        t_old = solver.t
        msg = solver.step()
        if solver.status == "failed":
            raise RuntimeError(f"reference solver failed at t = {t_old:.4f}: {msg}")
        dense = None
        while i < t_out.size and t_out[i] <= solver.t:
            if t_out[i] == solver.t:
                ys.append(solver.y.copy())
            else:
                dense = dense or solver.dense_output()
                ys.append(dense(t_out[i]))
            i += 1
    if solver.h_abs is not None and np.isfinite(solver.h_abs) and solver.h_abs > 0:
        carried.h = float(solver.h_abs)
    ys.append(solver.y.copy())
    return np.array(ys)
