import numpy as np

from ..components.base import Parameter, ParameterError
from .base import CITE_CATALOG, Effect, clip_grid


class Payload(Effect):
    """Extra point mass carried by the joint's child link at its payload point.

    Adds m to the link mass at the payload point (the end of the link, or the tool frame); negative
    values remove mass (a model that is too heavy). Gravity and inertia about every proximal joint
    grow: the load pressure rises, so lifting slows and lowering speeds up, by an amount that
    depends on the arm's configuration (cos of the link angle).
    """

    name = "payload"
    citation = CITE_CATALOG + " (§3.15)"
    PARAMETERS = (Parameter("mass", "kg", "point mass added at the payload point", 5.0, -1000.0, 5000.0,
                            absent=0.0),)   # a load set down
    switch = False          # changes the link's mass at lowering; no equations of its own
    MECHANISM = True        # lowered before the inertia-dependent parts (end stops, compliance)

    @classmethod
    def lower(cls, params, lw, a):
        body, point = lw.payload_point(a)
        m = params["mass"]
        m0 = lw.mass[body]
        c0 = lw.com[body].copy()
        m1 = m0 + m
        if m1 <= 0.05 * m0:
            raise ParameterError(f"payload: mass {m} kg leaves the link with {m1:.3g} kg; must stay positive")
        c1 = (m0 * c0 + m * point) / m1
        # inertia about the new COM: parallel-axis shift of the old body and the point mass
        d0 = c0 - c1
        dp = point - c1
        I = lw.inertia[body] + m0 * (d0 @ d0 * np.eye(3) - np.outer(d0, d0)) + m * (dp @ dp * np.eye(3) - np.outer(dp, dp))
        if np.linalg.eigvalsh(I).min() <= 0.0:
            raise ParameterError(f"payload: mass {m} kg makes the link inertia non-physical")
        lw.mass[body] = m1
        lw.com[body] = c1
        lw.inertia[body] = I

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        from ..model.queries import subtree_mass

        dof = spec.joint(joint).dof
        m = subtree_mass(spec.tree, dof)
        body = spec.tree.index(dof)
        lo, hi = -0.8 * float(spec.tree.mass[body]), 4.0 * m
        grid = [m * f for f in (-0.3, -0.1, 0.05, 0.15, 0.4, 1.0)]
        null = current["mass"] if current else 0.0
        return {"free": [("mass", lo, hi, False, null, "kg")], "fixed": {"mass": 0.0},
                "grid": [[v] for v in clip_grid(grid, lo, hi)]}
