"""Context: the parameters (a validated RobotSpec) and the state of one simulated robot.

Parameters are changed only through the context, which validates them by path and re-lowers the
kernel arrays while keeping the state; so a bad value is refused with its name and never reaches
the plant.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .components.chambers import P_A, P_B
from .components.potentiometer import SENS_ANGLE
from .components.pump import P_S, P_SUPPLY, P_TANK, SUPPLY_SAG
from .dynamics.rigid_body import RigidBodyModel
from .effects import EFFECTS
from .kernel import layout as L
from .lowering import KIND_CLASS, Lowered, lower
from .model.spec import RobotSpec

HISTORY_CAPACITY = 8192  # command events kept for the delay line (0.8 s at 10 kHz)


class Context:
    def __init__(self, plant, spec: RobotSpec | None = None, seed: int = 0, *, owned: bool = False):
        """``owned``: ``spec`` is the caller's private copy, which the context may keep (no copy)."""
        self.plant = plant
        spec = spec or plant.spec
        self.spec: RobotSpec = spec if owned else spec.copy()
        self.lowered: Lowered = lower(self.spec)
        n, na = self.spec.tree.n, len(self.spec.joints)
        self.XQ = np.zeros((2, n))
        self.XS = np.zeros((na, L.XS_N))
        self.XG = np.zeros(L.XG_N)
        self.HT = np.zeros(HISTORY_CAPACITY)
        self.HU = np.zeros((HISTORY_CAPACITY, na))
        self.rng = np.zeros(1, dtype=np.uint64)
        self.faults: dict[tuple[str, str], dict] = {}
        self.energy_ledger = False
        self.locked: set[str] = set()
        self.reset(seed)

    # ---- arrays the kernel reads ---------------------------------------------------------------
    @property
    def AP(self) -> np.ndarray:
        return self.lowered.AP

    @property
    def DP(self) -> np.ndarray:
        return self.lowered.DP

    @property
    def GP(self) -> np.ndarray:
        return self.lowered.GP

    @property
    def time(self) -> float:
        return float(self.XG[L.XG_TIME])

    @property
    def q(self) -> np.ndarray:
        return self.XQ[0]

    @property
    def qd(self) -> np.ndarray:
        return self.XQ[1]

    def rigid_body(self) -> RigidBodyModel:
        lw = self.lowered
        return RigidBodyModel(self.spec.tree, lw.mass, lw.com, lw.inertia)

    # ---- state ------------------------------------------------------------------------------
    def reset(self, seed: int | None = None, q0: np.ndarray | None = None) -> None:
        """Initial state: the spec's pose at rest, chambers pre-loaded to hold the arm still."""
        lw = self.lowered
        tree = self.spec.tree
        q = lw.q0.copy() if q0 is None else np.asarray(q0, dtype=float).copy()
        self.XQ[0] = q
        self.XQ[1] = 0.0
        self.XS[:] = 0.0
        self.XG[:] = 0.0
        self.HT[:] = 0.0
        self.HU[:] = 0.0
        if seed is not None:
            # splitmix64 of the seed: any integer gives a well-mixed, non-zero xorshift state
            z = (int(seed) + 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF
            z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
            z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
            self.rng[0] = np.uint64((z ^ (z >> 31)) or 1)
        GP, AP = lw.GP, lw.AP
        self.XG[P_S] = GP[P_SUPPLY] * GP[SUPPLY_SAG]
        gravity = self.rigid_body().inverse_dynamics(q, np.zeros(tree.n), np.zeros(tree.n))
        p_s, p_t = GP[P_SUPPLY], GP[P_TANK]
        pm = 0.5 * (p_s + p_t)
        for a, js in enumerate(self.spec.joints):
            dof = int(AP[a, L.AP_DOF])
            tau = gravity[dof]
            pa, pb = KIND_CLASS[js.kind].holding_pressures(AP[a], q[dof], tau, pm)
            self.XS[a, P_A] = float(np.clip(pa, p_t, p_s))
            self.XS[a, P_B] = float(np.clip(pb, p_t, p_s))
            self.XS[a, SENS_ANGLE] = q[dof]
            for eff in EFFECTS.values():
                eff.reset(self, a, q[dof], tau, self.effect_on(eff, a))

    def effect_on(self, eff, a: int) -> bool:
        """Whether effect class ``eff`` is switched on for actuator ``a`` (or globally)."""
        if eff.switch:
            return (self.GP[eff.switch_column] if eff.scope == "global" else self.AP[a, eff.switch_column]) != 0.0
        joint = self.spec.joint_names[a]
        return any(e.name == eff.name and e.joint in (joint, None) for e in self.spec.effects)

    def chamber_volumes(self, a: int) -> tuple[float, float]:
        """(V_A, V_B) of actuator ``a`` at its current position (m^3)."""
        from .effects.joint_compliance import TH_A

        th = self.XS[a, TH_A]
        return KIND_CLASS[self.spec.joints[a].kind].chamber_volumes(self.AP[a], th)

    def bulk_functions(self):
        """(beta, G): the oil's bulk modulus (Pa) and G(p) = int_0^p p'/f(p') dp' (Pa^2), f the
        pressure factor of the bulk modulus; compressed oil in a volume V stores V G(p) / beta."""
        import math

        from .components.fluid import ATM, BETA
        from .effects.bulk_modulus import BULK_PAIR, BULK_SCALE, BulkModulus

        GP = self.GP
        on = GP[BulkModulus.switch_column] != 0.0
        pa, s, pair = GP[ATM], GP[BULK_SCALE], GP[BULK_PAIR]

        def G(p):
            if not on:
                return 0.5 * p * p
            return (0.5 * p * p + pair * (p - pa * math.log((p + pa) / pa))) / s

        return GP[BETA], G

    # ---- parameters -------------------------------------------------------------------------
    def _relower(self) -> None:
        new = lower(self.spec)
        for key, mode in self.faults.items():
            _apply_fault(new, self.spec, key, mode)
        new.GP[L.GP_ENERGY] = 1.0 if self.energy_ledger else 0.0
        for dof in self.locked:
            new.DP[self.spec.tree.index(dof), L.DP_LOCKED] = 1.0
        self.lowered = new
        # states of effects that were off are kept in step by the kernel; nothing to re-initialise

    def set_parameter(self, path: str, value: Any) -> None:
        old = self.spec.get(path)
        self.spec.set(path, value)
        try:
            self._relower()
        except Exception:
            self.spec.set(path, old)
            raise

    def get_parameter(self, path: str) -> Any:
        return self.spec.get(path)

    def enable_effect(self, name: str, joint: str | None = None, **params):
        backup = list(self.spec.effects)
        inst = self.spec.enable_effect(name, joint, **params)
        try:
            self._relower()
        except Exception:
            self.spec.effects = backup
            raise
        return inst

    def disable_effect(self, name: str, joint: str | None = None) -> bool:
        changed = self.spec.disable_effect(name, joint)
        if changed:
            self._relower()
        return changed

    def apply_overrides(self, data: dict, where: str = "parameter file") -> None:
        self.spec.apply_overrides(data, where)
        self._relower()

    def lock(self, joints) -> None:
        """Hold these joints (actuated joint or URDF joint names) rigid at their current angles and stop
        simulating their actuators; the rest move with the correspondingly reduced dynamics. Used to
        identify one joint at a time, and by the identification for speed."""
        dofs = set()
        for name in joints:
            dofs.add(self.spec.joint(name).dof if name in self.spec.joint_names else self.spec.tree.dof_names[self.spec.tree.index(name)])
        self.locked = dofs
        self.XQ[1, [self.spec.tree.index(d) for d in dofs]] = 0.0
        self._relower()

    # ---- faults (HIL fault injection; cleared individually) ----------------------------------------
    def set_fault(self, joint: str | None, kind: str, **params) -> None:
        key = (joint or "", kind)
        mode = dict(params)
        _apply_fault(self.lowered, self.spec, key, mode)  # raises on an unknown kind or joint
        self.faults[key] = mode

    def clear_fault(self, joint: str | None, kind: str) -> bool:
        key = (joint or "", kind)
        if key not in self.faults:
            return False
        del self.faults[key]
        self._relower()
        return True

    def clear_faults(self) -> None:
        self.faults.clear()
        self._relower()


def _fault_owners() -> dict:
    """Fault kind -> the lowering function of the component it breaks."""
    from .components import Hose, Potentiometer, Pump, Spool, chambers

    owners = {}
    for owner, lower_fault in ((Potentiometer, Potentiometer.lower_fault), (Spool, Spool.lower_fault),
                               (chambers, chambers.lower_fault), (Hose, Hose.lower_fault), (Pump, Pump.lower_fault)):
        for kind in owner.FAULTS:
            owners[kind] = lower_fault
    return owners


FAULT_KINDS = ("sensor_stuck", "sensor_noisy", "sensor_offset", "spool_stuck", "leak", "hose_burst", "supply_sag")


def _apply_fault(lw: Lowered, spec: RobotSpec, key: tuple[str, str], mode: dict) -> None:
    joint, kind = key
    owners = _fault_owners()
    if kind not in owners:
        raise ValueError(f"unknown fault {kind!r}; faults: {', '.join(FAULT_KINDS)}")
    a = None if kind == "supply_sag" else spec.joint_names.index(joint)
    owners[kind](lw, a, kind, mode)
