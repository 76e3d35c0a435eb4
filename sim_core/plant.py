"""The Plant (a System in Drake's sense): the structure of one robot, built from its spec.

The plant knows which joints exist, what drives them and what is sensed. Numbers that can change
(parameters, switched effects) and the state belong to a :class:`~sim_core.context.Context`;
time stepping belongs to the :class:`~sim_core.simulator.Simulator`.
"""

from __future__ import annotations

from pathlib import Path

from .model.spec import RobotSpec, load_robot


class Plant:
    def __init__(self, spec: RobotSpec):
        self.spec = spec

    @classmethod
    def from_robot(cls, name_or_path: str | Path) -> "Plant":
        return cls(load_robot(name_or_path))

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def tree(self):
        return self.spec.tree

    @property
    def joint_names(self) -> list[str]:
        """Actuated (commandable) joints, in channel order."""
        return self.spec.joint_names

    @property
    def sensed_joints(self) -> list[str]:
        return self.spec.sensed_joints

    @property
    def dof_names(self) -> list[str]:
        """All moving URDF joints, actuated and passive."""
        return list(self.spec.tree.dof_names)

    def describe(self) -> dict:
        """Summary used by ``hydrohil robots --json``."""
        return {
            "name": self.spec.name,
            "description": self.spec.description,
            "reference": self.spec.reference,
            "urdf": self.spec.urdf_path.name,
            "joints": [
                {
                    "name": j.name,
                    "actuator": j.actuator_label,
                    "sensed": j.sensed,
                    "command_voltage_range": list(j.command_range),
                    "limits_rad": [float(self.tree.lower[self.tree.index(j.dof)]), float(self.tree.upper[self.tree.index(j.dof)])],
                }
                for j in self.spec.joints
            ],
            "passive_joints": list(self.spec.passive),
        }

    def create_context(self, spec: RobotSpec | None = None, seed: int = 0, *, owned: bool = False):
        """``owned``: ``spec`` is the caller's private copy (the context keeps it instead of copying)."""
        from .context import Context

        return Context(self, spec, seed=seed, owned=owned)
