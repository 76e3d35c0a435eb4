"""A robot spec and commands whose arrays are read-only (as Ray's object store hands them to a fleet's
workers: pickle protocol 5, buffers out of band) simulate on the kernel already compiled, with the
same result: numba would otherwise compile the whole kernel again for the read-only types."""

import pickle

import numpy as np
import pytest
from numba.core import event

from sim_core.dynamics.rigid_body import RigidBodyModel
from sim_core.plant import Plant
from sim_core.precompile import FAMILIES
from sim_core.simulator import Simulator


class _Compiles(event.Listener):
    def __init__(self):
        self.names = []

    def on_start(self, ev):
        f = getattr(ev.data.get("dispatcher"), "py_func", None)
        self.names.append(f"{getattr(f, '__module__', '?')}.{getattr(f, '__name__', '?')}")

    def on_end(self, ev):
        pass


def _through_object_store(obj):
    """What a Ray worker gets: pickle 5 with out-of-band buffers, each backed by immutable bytes."""
    buffers = []
    data = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    return pickle.loads(data, buffers=[memoryview(bytes(b.raw())) for b in buffers])


def _run(spec, t, U):
    return Simulator(Plant(spec).create_context(seed=3)).run(t, U)


@pytest.mark.parametrize("kind", list(FAMILIES))
def test_a_read_only_spec_and_commands_run_on_the_compiled_kernel(kind):
    spec = FAMILIES[kind]()
    t = np.arange(0.0, 0.5, 0.01)
    U = np.zeros((t.size, len(spec.joint_names)))
    U[10:, 0] = 2.0
    ref = _run(spec, t, U)                                # compiles or loads what a writable call needs
    RigidBodyModel(spec.tree).inverse_dynamics(ref.q[-1], ref.qd[-1], np.zeros(spec.tree.n))

    shipped = _through_object_store(spec)
    U_ro = _through_object_store(U)
    assert not shipped.tree.R_tree.flags.writeable and not U_ro.flags.writeable   # the case is real
    seen = _Compiles()
    with event.install_listener("numba:compile", seen):
        got = _run(shipped, t, U_ro)
        tau_ro = RigidBodyModel(shipped.tree).inverse_dynamics(_through_object_store(ref.q[-1]), ref.qd[-1],
                                                               np.zeros(spec.tree.n))
    assert seen.names == [], seen.names                   # nothing compiled for the read-only types
    np.testing.assert_array_equal(got.q, ref.q)
    np.testing.assert_array_equal(got.act, ref.act)
    np.testing.assert_array_equal(tau_ro, RigidBodyModel(spec.tree).inverse_dynamics(ref.q[-1], ref.qd[-1],
                                                                                      np.zeros(spec.tree.n)))
