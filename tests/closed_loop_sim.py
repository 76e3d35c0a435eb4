"""Records made under a P (or PI) controller: the simulated robot stepped at the controller's rate with
``u = Kp (r - y)`` computed from the sensor reading ``y`` (what a real closed-loop log holds), beside
an open-loop PRBS record of the same robot, joint and length. Both return dataset columns."""

from __future__ import annotations

import numpy as np

from sim_core.excitation import multilevel_prbs
from sim_core.kernel import layout as L
from sim_core.plant import Plant
from sim_core.simulator import Simulator


def step_reference(spec, joint: str, duration: float, rate: float, seed: int, hold: float = 3.0,
                   span: float = 0.25) -> np.ndarray:
    """Steps every ``hold`` s to levels within +-``span`` rad of the joint's initial position,
    inside its range."""
    rng = np.random.default_rng(seed)
    tree = spec.tree
    i = tree.index(spec.joint(joint).dof)
    q0 = float(spec.joint(joint).settings["initial_position"])
    lo, hi = max(float(tree.lower[i]) + 0.05, q0 - span), min(float(tree.upper[i]) - 0.05, q0 + span)
    n = int(round(duration * rate)) + 1
    per = int(round(hold * rate))
    levels = rng.uniform(lo, hi, size=n // per + 1)
    return np.repeat(levels, per)[:n]


def closed_loop_columns(spec, joint: str, *, kp: float, duration: float = 30.0, rate: float = 50.0,
                        seed: int = 0, reference: np.ndarray | None = None,
                        ti: float | None = None, settle_band: float = 0.0) -> dict[str, np.ndarray]:
    """Time, commands, readings and pressures of ``spec`` under ``u = kp (r - y)`` (V, clipped to
    the command range) on ``joint`` at ``rate`` Hz; ``y`` is the sensor reading (noise included).
    ``ti``: integral time (s) of a PI controller, ``u = kp (e + integral(e) / ti)``, its integral
    frozen while the command saturates; None: P only. ``settle_band`` (rad or m): once the error is
    within it, the controller parks the valve at 0 V, its integral frozen, until the error leaves twice
    it (a closed valve holds the joint without hunting)."""
    r = step_reference(spec, joint, duration, rate, seed) if reference is None else reference
    return loops_columns(spec, {joint: r}, kp=kp, rate=rate, seed=seed, ti=ti, settle_band=settle_band)


def loops_columns(spec, references: dict[str, np.ndarray], *, kp: float, rate: float = 50.0, seed: int = 0,
                  ti: float | None = None, settle_band: float = 0.0) -> dict[str, np.ndarray]:
    """``closed_loop_columns`` with a loop of its own on each joint of ``references`` (joint: its
    reference, all of one length), every loop with the same gains."""
    ctx = Plant(spec).create_context(seed=seed)
    sim = Simulator(ctx)
    n = next(iter(references.values())).size
    na = len(spec.joints)
    a = np.array([spec.joint_names.index(j) for j in references])
    R = np.stack([references[j] for j in references], axis=1)
    lo, hi = (np.array(v, dtype=float) for v in zip(*(spec.joint(j).command_range for j in references)))
    U = np.zeros((n, na))
    Y = np.zeros((n, na, L.YA_N))
    dt = 1.0 / rate
    row = sim.sample()
    integral, parked = np.zeros(a.size), np.zeros(a.size, dtype=bool)
    for k in range(n):
        Y[k] = row
        e = R[k] - row[a, L.YA_ANGLE]
        parked = np.abs(e) < np.where(parked, 2.0, 1.0) * settle_band
        raw = np.where(parked, 0.0, kp * (e + (integral / ti if ti else 0.0)))
        U[k, a] = np.minimum(np.maximum(raw, lo), hi)
        if ti:
            integral += np.where(~parked & (U[k, a] == raw), e * dt, 0.0)
        if k < n - 1:
            row = sim.step(U[k], dt).copy()
    return _columns(spec, np.arange(n) * dt, U, Y)


def open_loop_columns(spec, joint: str, *, duration: float = 30.0, rate: float = 50.0, seed: int = 0,
                      amplitude: float = 4.0) -> dict[str, np.ndarray]:
    """The same robot driven by a multi-level PRBS on ``joint`` (range guard on)."""
    t, U = multilevel_prbs(spec, joint, levels=5, amplitude=amplitude, duration=duration, rate=rate, seed=seed)
    ctx = Plant(spec).create_context(seed=seed)
    traj = Simulator(ctx).run(t, U)
    return _columns(spec, t, U, traj.act)


def _columns(spec, t, U, Y) -> dict[str, np.ndarray]:
    cols = {"time": t}
    for a, j in enumerate(spec.joint_names):
        cols[f"u_{j}"] = U[:, a]
    for a, js in enumerate(spec.joints):
        if js.sensed:
            cols[f"q_{js.name}"] = Y[:, a, L.YA_ANGLE]
    return cols
