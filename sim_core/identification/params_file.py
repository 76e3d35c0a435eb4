"""Parameter/effect files (the ``--params`` format) written by ``fit`` and ``diagnose``.

The file holds everything that differs from the robot's built-in spec, so ``hydrohil simulate
--params`` and ``hydrohil serve --params`` rebuild exactly the fitted model from the robot's name:
changed parameter paths, effects switched on or changed, effects of the built-in spec switched off
(``enabled = false``), and a ``[diagnosis]`` table with the provenance (ignored when loading).
"""

from __future__ import annotations

import math
from pathlib import Path

import tomli_w

from ..model.spec import load_robot


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
