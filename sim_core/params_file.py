"""Parameter/effect files (the ``--params`` format): the one reader and writer.

The file holds everything that differs from the robot's built-in spec, so ``hydrohil simulate
--params`` and ``hydrohil serve --params`` rebuild exactly the fitted model from the robot's name:
changed parameter paths, effects switched on or changed, effects of the built-in spec switched off
(``enabled = false``), and a ``[diagnosis]`` table with the provenance (ignored when loading).
``fit`` and ``diagnose`` write it; the CLI, the HIL service and the controllers read it here.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import tomli_w

from .model.spec import RobotSpec, SpecError, load_robot


class ParamsFileError(ValueError):
    """A parameter file cannot be read or does not fit the robot (the message names the file)."""


def read_params_file(path: str | Path) -> dict:
    """The parsed TOML of a parameter file; :class:`ParamsFileError` naming the file otherwise."""
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ParamsFileError(f"--params {path}: no such file") from None
    except IsADirectoryError:
        raise ParamsFileError(f"--params {path}: is a directory, not a TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ParamsFileError(f"--params {path}: invalid TOML: {exc}") from None


def apply_params_file(spec: RobotSpec, path: str | Path) -> RobotSpec:
    """Apply the file's ``[parameters]`` and ``[[effects]]`` to ``spec`` (in place, returned)."""
    data = read_params_file(path)
    try:
        spec.apply_overrides(data, where=f"--params {path}")
    except SpecError as exc:
        raise ParamsFileError(str(exc)) from None
    return spec


def _same(a, b) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return a == b or (math.isfinite(a) and math.isfinite(b) and abs(a - b) <= 1e-12 * max(abs(a), abs(b)))
    return a == b


def overrides(spec, reference=None) -> dict:
    """The ``[parameters]`` and ``[[effects]]`` that turn ``reference`` (default: the robot's built-in
    spec, loaded from the same file) into ``spec``."""
    if reference is None:
        reference = load_robot(spec.source or spec.name)
    ref_p = reference.parameters()
    params = {}
    for path, v in spec.parameters().items():
        if path not in ref_p or not _same(ref_p[path], v):
            params[path] = list(v) if isinstance(v, tuple) else v
    effects = []
    ref_e = {(e.name, e.joint): e for e in reference.effects}
    for e in spec.effects:
        r = ref_e.get((e.name, e.joint))
        if r is None or any(not _same(r.params.get(k), v) for k, v in e.params.items()):
            effects.append(e.to_dict())
    have = {(e.name, e.joint) for e in spec.effects}
    for (name, joint), e in ref_e.items():
        if (name, joint) not in have:
            d = {"name": name}
            if joint is not None:
                d["joint"] = joint
            d["enabled"] = False
            effects.append(d)
    out: dict = {"robot": spec.name}
    if params:
        out["parameters"] = params
    if effects:
        out["effects"] = effects
    return out


def _clean(v):
    """TOML has no null or non-finite floats: drop None, write inf/nan as strings."""
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items() if x is not None}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v if x is not None]
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    if hasattr(v, "item"):
        return _clean(v.item())
    return v


def write_params(path: str | Path, data: dict, header: str = "") -> None:
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    text = tomli_w.dumps(_clean(data))
    if header:
        text = "".join(f"# {line}\n" for line in header.splitlines()) + text
    path.write_text(text)
