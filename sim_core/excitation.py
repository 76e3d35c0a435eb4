"""Multi-level pseudo-random excitation, as used to validate the MARS-ND joint-2 model (Fig. 14).

A clocked multi-level PRBS: every ``period`` seconds the command takes one of ``levels`` equally
spaced values in [-amplitude, amplitude], drawn uniformly from a seeded generator. A hydraulic
joint integrates its command, so a purely random sequence wanders into an end stop; with the range
guard on (default) the nominal model is simulated alongside, and a level that would carry the joint
past a margin inside its limits within the next period is mirrored to the opposite sign
(the research note's input design: signs chosen from the nominal model's state).
"""

from __future__ import annotations

import numpy as np


def prbs_levels(levels: int, amplitude: float) -> np.ndarray:
    if levels < 2:
        raise ValueError("--levels must be at least 2")
    if not amplitude > 0:
        raise ValueError("--amplitude must be positive")
    return np.linspace(-amplitude, amplitude, levels)


def multilevel_prbs(
    spec,
    joint: str,
    *,
    levels: int,
    amplitude: float,
    duration: float,
    rate: float,
    seed: int,
    period: float = 0.5,
    guard: bool = True,
    margin: float = 0.15,
):
    """Return (time [N], U [N, n_act]) with only ``joint`` excited."""
    js = spec.joint(joint)
    lo_v, hi_v = js.command_range
    if amplitude > min(-lo_v, hi_v):
        raise ValueError(f"--amplitude {amplitude} V exceeds joint {joint}'s command range [{lo_v}, {hi_v}] V")
    if not duration > 0 or not rate > 0:
        raise ValueError("--duration and --rate must be positive")
    if not period > 0:
        raise ValueError("--period must be positive")
    n = int(round(duration * rate)) + 1
    t = np.arange(n) / rate
    vals = prbs_levels(levels, amplitude)
    rng = np.random.default_rng(seed)
    a = spec.joint_names.index(joint)
    U = np.zeros((n, len(spec.joint_names)))
    clock = max(1, int(round(period * rate)))
    if not guard:
        for k0 in range(0, n, clock):
            U[k0:k0 + clock, a] = vals[rng.integers(len(vals))]
        return t, U

    from .plant import Plant
    from .simulator import Simulator

    ctx = Plant(spec).create_context()
    sim = Simulator(ctx)
    dof = spec.tree.index(js.dof)
    lo, hi = spec.tree.lower[dof], spec.tree.upper[dof]
    span = hi - lo
    lo_m, hi_m = lo + margin * span, hi - margin * span
    probe = Plant(spec).create_context()
    probe_sim = Simulator(probe)
    for k0 in range(0, n - 1, clock):
        k1 = min(k0 + clock, n - 1)
        level = vals[rng.integers(len(vals))]
        seg_t = t[k0:k1 + 1]
        if level != 0.0:
            # predict the end of this period from the current nominal state
            probe.XQ[:] = ctx.XQ
            probe.XS[:] = ctx.XS
            probe.XG[:] = ctx.XG
            seg_u = np.zeros((seg_t.size, U.shape[1]))
            seg_u[:, a] = level
            q_end = probe_sim.run(seg_t, seg_u).q[-1, dof]
            if q_end > hi_m and level > 0 or q_end < lo_m and level < 0:
                level = -level
        U[k0:k1, a] = level
        seg_u = np.zeros((seg_t.size, U.shape[1]))
        seg_u[:, a] = level
        sim.run(seg_t, seg_u)
    U[-1, a] = U[-2, a]
    return t, U
