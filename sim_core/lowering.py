"""Lowering: a validated :class:`RobotSpec` -> the dense arrays the compiled kernel reads.

Each component and effect writes its own columns (``lower``); this module only walks the spec in
the right order: actuator components, the effects' neutral values, the links' mass scale and the
effects that change the mechanism (payload), the joints (end stops need the final inertia), the
globals, the other effects.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .components import ACTUATOR_KINDS
from .components.joint import lower_joint
from .dynamics.rigid_body import RigidBodyModel
from .effects import EFFECTS, get_effect
from .kernel import layout as L
from .model.spec import RobotSpec

KIND_ID = {cls.KIND: float(i) for i, cls in enumerate(ACTUATOR_KINDS)}
KIND_CLASS = {cls.KIND: cls for cls in ACTUATOR_KINDS}


@dataclass
class Lowered:
    AP: np.ndarray
    DP: np.ndarray
    GP: np.ndarray
    mass: np.ndarray
    com: np.ndarray
    inertia: np.ndarray
    joint_inertia: np.ndarray   # M_ii at the initial pose (kg m^2)
    q0: np.ndarray
    spec: RobotSpec

    def payload_point(self, a: int) -> tuple[int, np.ndarray]:
        """(body index, point in body frame) where a payload on actuator ``a``'s joint attaches."""
        js = self.spec.joints[a]
        tree = self.spec.tree
        frame = js.settings["payload_frame"]
        if frame:
            body, _R, p = tree.link_frames[frame]
            if body < 0:
                raise ValueError(f"payload_frame {frame!r} is fixed to the ground")
            return body, np.array(p)
        i = tree.index(js.dof)
        for c in range(tree.n):
            if tree.parent[c] == i:
                return i, tree.p_tree[c].copy()
        return i, self.com[i].copy()


def initial_positions(spec: RobotSpec) -> np.ndarray:
    q0 = np.zeros(spec.tree.n)
    for j in spec.joints:
        q0[spec.tree.index(j.dof)] = j.settings["initial_position"]
    for dof, s in spec.passive.items():
        q0[spec.tree.index(dof)] = s["initial_position"]
    return q0


def lower(spec: RobotSpec) -> Lowered:
    tree = spec.tree
    n, na = tree.n, len(spec.joints)
    L._load_owners()
    AP = np.zeros((na, L.AP_N))
    DP = np.zeros((n, L.DP_N))
    GP = np.zeros(L.GP_N)
    q0 = initial_positions(spec)
    lw = Lowered(AP, DP, GP, tree.mass.copy(), tree.com.copy(), tree.inertia.copy(), np.zeros(n), q0, spec)
    spec.links.lower_masses(lw)

    # --- actuators: every component of the joint's chain writes its columns
    for a, js in enumerate(spec.joints):
        AP[a, L.AP_DOF] = tree.index(js.dof)
        AP[a, L.AP_KIND] = KIND_ID[js.kind]
        for comp in js.components.values():
            comp.lower(lw, a, spec, js)
        for eff in EFFECTS.values():
            eff.lower_neutral(lw, a)

    # --- mechanism: effects that change masses first, then what depends on the inertia
    effects = sorted(spec.effects, key=lambda e: not get_effect(e.name).MECHANISM)
    for e in effects:
        if get_effect(e.name).MECHANISM:
            get_effect(e.name).lower(e.params, lw, spec.joint_names.index(e.joint))
    rb = RigidBodyModel(tree, lw.mass, lw.com, lw.inertia)
    lw.joint_inertia[:] = np.diag(rb.mass_matrix(q0))
    p_supply = spec.supply["pressure"]
    driven = {tree.index(js.dof): a for a, js in enumerate(spec.joints)}
    for i in range(n):
        a = driven.get(i)
        tau_max = 0.0
        if a is not None:
            tau_max = KIND_CLASS[spec.joints[a].kind].max_force(AP[a], tree.lower[i], tree.upper[i], p_supply)
        lower_joint(DP, i, tree.lower[i], tree.upper[i], tree.damping[i], lw.joint_inertia[i], tau_max,
                    spec.integrator, -1 if a is None else a)

    # --- globals
    spec.supply.lower_global(lw, spec)
    spec.fluid.lower_global(lw, spec)
    GP[L.GP_H_MAX] = spec.integrator["max_substep"]
    GP[L.GP_RB_EVERY] = spec.integrator["rigid_body_refresh"]
    GP[L.GP_JAC_TOL] = spec.integrator["jacobian_tolerance"]

    for e in effects:
        eff = get_effect(e.name)
        if eff.MECHANISM:
            continue
        eff.lower(e.params, lw, None if e.joint is None else spec.joint_names.index(e.joint))
    return lw
