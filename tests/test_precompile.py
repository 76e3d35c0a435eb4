"""Precompiling the kernel covers every signature it is compiled for, and leaves it in the cache
that later processes load from (``make test`` runs it before its parallel pass)."""

import subprocess
import sys

import numpy as np

from sim_core import precompile
from sim_core.kernel.workspace import tree_arrays
from sim_core.lowering import lower
from sim_core.model.urdf import PRISMATIC


def test_one_robot_for_each_signature_of_the_kernel():
    seen = {}
    for kind, spec in precompile.family_specs().items():
        jtype = tree_arrays(spec.tree, lower(spec)).jtype
        seen[kind] = "all revolute" if jtype is None else tuple(sorted(set(np.asarray(jtype).tolist())))
    assert seen["revolute"] == "all revolute"
    assert PRISMATIC in seen["prismatic"], seen
    assert len(set(seen.values())) == len(seen)      # no kind repeats another's signature


def test_a_second_run_loads_every_kind_from_the_cache_the_first_left():
    def run():
        p = subprocess.run([sys.executable, "-m", "sim_core.precompile"], capture_output=True, text=True, timeout=900)
        assert p.returncode == 0, p.stderr
        assert "Traceback" not in p.stderr
        return p.stdout
    run()                                            # compiles only where nothing was cached yet
    second = run()
    for kind in ("revolute", "prismatic"):
        assert f"{kind} from the cache" in second, second
    assert "compiled" not in second, second
