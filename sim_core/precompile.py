"""Compile the simulation kernel into the kernel cache before anything needs it.

numba compiles the composed kernel once per kind of robot (an all-revolute tree, and a tree with a
prismatic joint, whose joint types reach the kernel as an array: another signature) and caches the
machine code. A process that finds no cache entry compiles its own copy, one to three minutes on a
small machine, so processes started together on a fresh machine (the test workers of ``make
test``, a fleet's pool, a service and its clients) each compile the same code side by side. This
compiles every kind at once, one process each, so that they all load it instead.

``python -m sim_core.precompile [--reference]``: ``--reference`` also compiles the reference
solver's right-hand side (``hydrohil bench``, the physics tests).
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor


def _revolute_robot():
    from .model.spec import load_robot

    return load_robot("hydrolek")


def _prismatic_robot():
    """A ``cylinder`` template rig: a load on a prismatic joint."""
    from .model.spec import load_robot
    from .rigs import new_rig

    with tempfile.TemporaryDirectory(prefix="hydrohil-precompile-") as tmp:
        new_rig("cylinder", tmp)
        return load_robot(tmp)


# {kind: a function that loads a robot of that kind}: one robot for every argument signature of the kernel
FAMILIES = {"revolute": _revolute_robot, "prismatic": _prismatic_robot}


def family_specs() -> dict:
    """{kind: a robot spec of that kind} for every kind in :data:`FAMILIES`."""
    return {kind: load() for kind, load in FAMILIES.items()}


def warm(kind: str, reference: bool = False) -> dict:
    """Load or compile the kernel for one kind of robot; says which it was and how long it took (s)."""
    import numpy as np

    from .kernel.compile_notice import on_kernel_compile
    from .plant import Plant
    from .simulator import Simulator

    t0 = time.perf_counter()
    spec = FAMILIES[kind]()
    compiled: list[bool] = []
    t = np.arange(0.0, 0.1, 0.01)
    U = np.zeros((t.size, len(spec.joint_names)))
    with on_kernel_compile(lambda: compiled.append(True)):
        Simulator(Plant(spec).create_context(seed=0)).run(t, U)
        if reference:
            from .reference import solve_reference

            solve_reference(Plant(spec).create_context(seed=0), t, U, method="Radau", rtol=1e-6)
    return {"kind": kind, "compiled": bool(compiled), "seconds": time.perf_counter() - t0}


def precompile(reference: bool = False) -> list[dict]:
    """Every kind side by side, each in a fresh process (numba's compiler holds one core each)."""
    kinds = tuple(FAMILIES)
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=len(kinds), mp_context=ctx) as pool:
        return list(pool.map(warm, kinds, [reference] * len(kinds)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sim_core.precompile", description=__doc__.split("\n\n")[0])
    ap.add_argument("--reference", action="store_true", help="also compile the reference solver's right-hand side")
    args = ap.parse_args(argv)
    from .kernel.compose import cache_dir

    t0 = time.perf_counter()
    try:
        done = precompile(args.reference)
    except Exception as exc:     # noqa: BLE001 - a broken kernel shows again, with its detail, where it is used
        print(f"precompile: failed ({type(exc).__name__}: {exc})", file=sys.stderr)
        return 1
    said = ", ".join(f"{d['kind']} {'compiled' if d['compiled'] else 'from the cache'} in {d['seconds']:.1f} s"
                     for d in done)
    print(f"precompile: {said}; {time.perf_counter() - t0:.1f} s in all, cache {cache_dir()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
