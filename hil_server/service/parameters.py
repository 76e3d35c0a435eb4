"""The parameter mirror: the service's copy of the engine's RobotSpec.

Every change is validated here first (on a copy, all or nothing), then sent to the engine, and only
kept when the engine applied it too. REST reads parameters from this copy; a restarted engine starts
from it."""

from __future__ import annotations

import threading

from sim_core.effects import catalog
from sim_core.model.spec import RobotSpec, SpecError, load_robot
from sim_core.params_file import overrides

from .config import ServiceError
from .engine_calls import engine_call


class ParameterMirror:
    def __init__(self, spec: RobotSpec, engine):
        self.spec = spec
        self.engine = engine            # anything with request(op, *args) -> reply (the supervisor)
        self._lock = threading.Lock()

    @property
    def joint_names(self) -> list[str]:
        return self.spec.joint_names

    def parameters(self) -> dict:
        return {"robot": self.spec.name, "values": self.spec.parameters(),
                "effects": [e.to_dict() for e in self.spec.effects]}

    def value(self, path: str):
        values = self.spec.parameters()
        if path not in values:
            raise ServiceError(f"unknown parameter path {path!r}", 404)
        return values[path]

    def changed_from_defaults(self) -> dict:
        """Parameters and effects that differ from the robot's built-in spec (for fault reports)."""
        return overrides(self.spec, load_robot(self.spec.source or self.spec.name))

    def _change(self, mutate, op: str, *args):
        with self._lock:
            trial = self.spec.copy()
            try:
                mutate(trial)
            except SpecError as exc:
                raise ServiceError(str(exc)) from None
            out = engine_call(self.engine, op, *args)
            self.spec = trial
            return out

    def patch(self, values: dict) -> dict:
        def mutate(trial):
            for path, v in values.items():
                trial.set(path, v)
        return self._change(mutate, "set_parameters", values)

    def effects(self) -> dict:
        return {"catalog": catalog(), "enabled": [e.to_dict() for e in self.spec.effects]}

    def enable_effect(self, name: str, joint: str | None, params: dict) -> dict:
        return self._change(lambda trial: trial.enable_effect(name, joint, **params), "enable_effect", name, joint, params)

    def disable_effect(self, name: str, joint: str | None) -> dict:
        def mutate(trial):
            if not trial.disable_effect(name, joint):
                raise ServiceError(f"effect {name} on {joint} is not enabled", 404)
        return self._change(mutate, "disable_effect", name, joint)
