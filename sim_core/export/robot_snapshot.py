"""A robot spec as one self-contained ``robot.toml`` beside a copy of its URDF.

A robot's own ``robot.toml`` may lean on things outside it: ``[defaults]`` tables, ``[[arms]]`` that
name another built-in robot, the installed package's version of that robot. An exported model must
not change when those do, so the snapshot writes every parameter of every component explicitly,
arms already expanded and prefixed, effects as ``[[effects]]``; :func:`sim_core.model.spec.load_robot`
reads it back to an equal spec (same :meth:`RobotSpec.parameters` and effects).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import tomli_w


def _plain(values: dict) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}


def snapshot_data(spec) -> dict:
    """The TOML tables of a standalone robot file that loads back to ``spec``."""
    joints = {}
    for j in spec.joints:
        table = {"dof": j.dof, **_plain(j.settings.values)}
        for sec, comp in j.components.items():
            table[sec] = _plain(comp.values)
        joints[j.name] = table
    data = {
        "robot": {"name": spec.name, "description": spec.description, "reference": spec.reference,
                  "urdf": spec.urdf_path.name},
        "integrator": _plain(spec.integrator.values),
        "fluid": _plain(spec.fluid.values),
        "supply": _plain(spec.supply.values),
        "links": _plain(spec.links.values),
        "joints": joints,
    }
    if spec.passive:
        data["passive"] = {d: _plain(s.values) for d, s in spec.passive.items()}
    if spec.effects:
        data["effects"] = [_plain(e.to_dict()) for e in spec.effects]
    if spec.estimated:
        data["estimated"] = {path: list(bounds) for path, bounds in spec.estimated.items()}
    return data


def write_snapshot(spec, folder: str | Path, header: str = "") -> Path:
    """Write ``folder/robot.toml`` and a copy of the URDF; return the robot file's path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(spec.urdf_path, folder / spec.urdf_path.name)
    text = tomli_w.dumps(snapshot_data(spec))
    if header:
        text = "".join(f"# {line}\n" for line in header.splitlines()) + text
    path = folder / "robot.toml"
    path.write_text(text)
    return path
