"""Small drivers shared by the physics tests."""

import numpy as np

from sim_core.simulator import Simulator


def step(v, t0=0.2, t1=1.2):
    return lambda t: np.where((t >= t0) & (t < t1), v, 0.0)


def run_joint(plant, joint, profile, *, effects=(), T=3.0, dt=1e-3, params=None, ctx=None):
    """Command one joint with ``profile(t)`` (others 0 V); returns (t, true angle, trajectory, context)."""
    if ctx is None:
        spec = plant.spec.copy()
        for path, value in (params or {}).items():
            spec.set(path, value)
        for name, j, kw in effects:
            spec.enable_effect(name, j, **kw)
        ctx = plant.create_context(spec)
    t = np.arange(0.0, T + 1e-9, dt)
    U = np.zeros((t.size, len(plant.joint_names)))
    U[:, plant.joint_names.index(joint)] = profile(t)
    tr = Simulator(ctx).run(t, U)
    i = plant.tree.index(plant.spec.joint(joint).dof)
    return t, tr.q[:, i], tr, ctx
