"""Compose the compiled kernel from the registered components and effects.

The skeleton (``skeleton.py``) holds the structure of a substep; every effect contributes its hooks
(``Effect.HOOKS``) to the phases of ``hooks.PHASES`` and every actuator kind (a component with a
``KIND``) its force, geometry and cached quantities. This module writes the composed phase
functions and the actuator dispatch into the skeleton, and stores the result as a Python file in
the kernel cache (``$HYDROHIL_KERNEL_CACHE``, else ``$XDG_CACHE_HOME/hydrohil/kernels``), named by
a hash of everything numba compiles into it: the skeleton, the generated text, the column layout
and the source of every module it calls. numba caches the machine code beside that file, so a
change to any kernel, component, effect or dynamics module, or to the layout, gives a new file and
a fresh compile; stale machine code cannot run against new columns.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
from pathlib import Path

import numba

from . import layout
from .hooks import OFF_ARGS, PHASES, Phase, hook_phase

SKELETON = Path(__file__).with_name("skeleton.py")
PACKAGE = Path(__file__).resolve().parent.parent
SOURCE_DIRS = ("kernel", "components", "effects", "dynamics")
KEEP = 12  # kernels kept in the cache directory
MODULE_PREFIX = "hydrohil_kernel_"  # the generated module's name: the prefix, then the source key


class CompositionError(RuntimeError):
    """Two effects claim one override phase, or a hook names a function its module lacks."""


def _effects():
    from ..effects import EFFECTS

    return list(EFFECTS.values())


def _actuator_kinds():
    from ..components import ACTUATOR_KINDS

    return ACTUATOR_KINDS


def _hook_refs():
    """{phase: [(effect class, alias, is_off)]} sorted by the effects' ORDER, plus imports."""
    refs: dict[str, list] = {p.name: [] for p in PHASES}
    imports: list[str] = []
    for eff in sorted(_effects(), key=lambda e: e.ORDER):
        mod = sys.modules[eff.__module__]
        for hook, fname in eff.HOOKS.items():
            phase, off = hook_phase(hook)
            if not hasattr(mod, fname):
                raise CompositionError(f"effect {eff.name!r}: hook {hook} names {fname!r}, which {eff.__module__} lacks")
            alias = f"_{eff.name}__{fname}"
            imports.append(f"from {eff.__module__} import {fname} as {alias}")
            refs[phase.name].append((eff, alias, off))
    return refs, imports


def _switch(eff, phase: Phase) -> str | None:
    if not eff.switch:
        return None
    if eff.scope == "global":
        return f"GP[{eff.switch_column}] != 0.0"
    return f"AP[a, {eff.switch_column}] != 0.0"


def _phase_function(phase: Phase, hooks: list) -> str:
    ons = [(e, al) for e, al, off in hooks if not off]
    offs = {e.name: al for e, al, off in hooks if off}
    lines = ["@njit(inline=\"always\")", f"def fx_{phase.name}({phase.args}):",
             f"    \"\"\"{phase.doc}\"\"\""]
    body: list[str] = []

    def guarded(eff, on_lines, off_lines):
        cond = _switch(eff, phase)
        if cond is None:
            body.extend("    " + s for s in on_lines)
            return
        body.append(f"    if {cond}:")
        body.extend("        " + s for s in on_lines)
        if off_lines:
            body.append("    else:")
            body.extend("        " + s for s in off_lines)

    def off_call(eff):
        if eff.name not in offs:
            return []
        return [f"{offs[eff.name]}({OFF_ARGS.get(phase.name, phase.args)})"]

    effs_with_off = [e for e, al, off in hooks if off and all(e is not x for x, _ in ons)]
    if effs_with_off:
        raise CompositionError(f"phase {phase.name}: {effs_with_off[0].name} has an off hook without an on hook")
    if phase.mode == "chain":
        for eff, al in ons:
            guarded(eff, [f"{phase.values} = {al}({phase.args})"], off_call(eff))
        body.append(f"    return {phase.values}")
    elif phase.mode == "override":
        if len(ons) > 1:
            raise CompositionError(f"phase {phase.name}: both {ons[0][0].name} and {ons[1][0].name} replace it")
        if ons:
            eff, al = ons[0]
            guarded(eff, [f"return {al}({phase.args})"], off_call(eff))
        body.append(f"    return {phase.default}")
    elif phase.mode == "sum":
        names = [v.strip() for v in phase.values.split(",")]
        body.extend(f"    {v} = 0.0" for v in names)
        for eff, al in ons:
            tmp = ", ".join(f"_{v}" for v in names)
            guarded(eff, [f"{tmp} = {al}({phase.args})"] + [f"{v} += _{v}" for v in names], off_call(eff))
        body.append(f"    return {phase.values}")
    elif phase.mode == "notify":
        for eff, al in ons:
            guarded(eff, [f"{al}({phase.args})"], off_call(eff))
        if not body:
            body.append("    pass")
    else:  # pragma: no cover - the phase table is ours
        raise CompositionError(f"phase {phase.name}: unknown mode {phase.mode}")
    return "\n".join(lines + body) + "\n"


def _actuator_dispatch() -> tuple[str, list[str]]:
    kinds = _actuator_kinds()
    imports = []
    parts = []
    for op, args, doc in (("prime", "a, th, AP, XS", "cache per-actuator quantities at position th"),
                          ("force", "a, AP, XS", "(force on the joint, viscous slope) from the chamber pressures"),
                          ("geometry", "a, th, om, AP, XS", "(V_A, V_B, Q_disp,A, Q_disp,B, dV_A/dt, dV_B/dt)")):
        lines = ["@njit(inline=\"always\")", f"def act_{op}({args}):", f"    \"\"\"{doc}\"\"\"",
                 "    kind = AP[a, AP_KIND]"]
        for kid, cls in enumerate(kinds):
            fname = cls.KERNEL[op]
            alias = f"_{cls.KIND}__{fname}"
            imports.append(f"from {cls.__module__} import {fname} as {alias}")
            if kid < len(kinds) - 1:
                lines.append(f"    if kind == {float(kid)!r}:")
                lines.append(f"        return {alias}({args})")
            else:
                lines.append(f"    return {alias}({args})")
        parts.append("\n".join(lines) + "\n")
    return "\n\n".join(parts), imports


def generate() -> str:
    """The complete kernel source for the registered components and effects."""
    layout._load_owners()
    refs, imports = _hook_refs()
    phases = "\n\n".join(_phase_function(p, refs[p.name]) for p in PHASES)
    dispatch, act_imports = _actuator_dispatch()
    composed = "\n".join(sorted(set(imports))) + "\n\n\n" + phases
    text = SKELETON.read_text()
    text = text.replace("# @COMPOSED@", composed.rstrip() + "\n")
    text = text.replace("# @ACTUATORS@", "\n".join(sorted(set(act_imports))) + "\n\n\n" + dispatch.rstrip() + "\n")
    return text


def source_key(text: str, sources: dict[str, bytes] | None = None) -> str:
    """Hash of the generated text, the layout, numba's version and every source it inlines."""
    if sources is None:
        sources = {}
        for d in SOURCE_DIRS:
            for p in sorted((PACKAGE / d).glob("*.py")):
                sources[f"{d}/{p.name}"] = p.read_bytes()
    h = hashlib.sha256()
    h.update(text.encode())
    h.update(layout.fingerprint().encode())
    h.update(numba.__version__.encode())
    h.update(sys.version.encode())
    for name in sorted(sources):
        h.update(name.encode())
        h.update(sources[name])
    return h.hexdigest()[:20]


def cache_dir() -> Path:
    env = os.environ.get("HYDROHIL_KERNEL_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "hydrohil" / "kernels"


def _write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp_", suffix=".py")
    with os.fdopen(fd, "w") as fh:
        fh.write(text)
    os.replace(tmp, path)


def _prune(root: Path, keep: Path) -> None:
    """Keep the newest kernels; an old one is only ever removed whole."""
    try:
        dirs = sorted((d for d in root.iterdir() if d.is_dir() and d.name.startswith("k_")),
                      key=lambda d: d.stat().st_mtime, reverse=True)
    except OSError:
        return
    import shutil

    for d in dirs[KEEP:]:
        if d != keep:
            shutil.rmtree(d, ignore_errors=True)


_MODULE = None
_MODULE_SIG = None


def kernel():
    """The compiled kernel module for the current components, effects and layout (built once per
    set of registered effects and layout)."""
    global _MODULE, _MODULE_SIG
    from ..effects import EFFECTS

    sig = (tuple(EFFECTS), layout.fingerprint())
    if _MODULE is not None and sig == _MODULE_SIG:
        return _MODULE
    text = generate()
    key = source_key(text)
    name = f"{MODULE_PREFIX}{key}"
    root = cache_dir()
    d = root / f"k_{key}"
    path = d / f"{name}.py"
    if not path.is_file() or path.read_text() != text:
        _write_atomic(path, text)
        _prune(root, d)
    os.utime(d)
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    _MODULE, _MODULE_SIG = mod, sig
    return mod
