"""Prismatic joints in the kinematic tree and the rigid-body dynamics, against Pinocchio.

The fixture tests/data/mixed_prismatic.urdf is a branched tree mixing revolute, continuous and
prismatic joints (a prismatic joint on the fixed root, prismatic under revolute and under
prismatic-revolute, revolute under prismatic), with oblique axes, rotated origins and links merged
through fixed joints. q is in rad for revolute joints and in m for prismatic ones.
"""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sim_core.dynamics import rigid_body as rb
from sim_core.dynamics.rigid_body import RigidBodyModel, RigidBodyWorkspace
from sim_core.kernel.compose import kernel
from sim_core.kernel.workspace import TreeArrays, make_workspace
from sim_core.model.urdf import PRISMATIC, REVOLUTE, UrdfError, load_urdf

URDF = Path(__file__).parent / "data" / "mixed_prismatic.urdf"


class PinMap:
    """Our joint order -> Pinocchio's configuration/velocity vectors (continuous joints take
    (cos q, sin q) in Pinocchio's configuration)."""

    def __init__(self, tree, model):
        self.model = model
        self.joints = [model.joints[model.getJointId(n)] for n in tree.dof_names]

    def q(self, q):
        qp = np.zeros(self.model.nq)
        for jm, qi in zip(self.joints, q):
            if jm.nq == 2:
                qp[jm.idx_q:jm.idx_q + 2] = np.cos(qi), np.sin(qi)
            else:
                qp[jm.idx_q] = qi
        return qp

    def v(self, v):
        vp = np.zeros(self.model.nv)
        vp[[jm.idx_v for jm in self.joints]] = v
        return vp

    def back(self, vp):
        return np.asarray(vp)[[jm.idx_v for jm in self.joints]]

    def matrix(self, Mp):
        Mp = np.triu(Mp) + np.triu(Mp, 1).T
        idx = [jm.idx_v for jm in self.joints]
        return Mp[np.ix_(idx, idx)]


@pytest.fixture(scope="module")
def setup():
    tree = load_urdf(URDF)
    model = pin.buildModelFromUrdf(str(URDF))
    return tree, model, model.createData(), PinMap(tree, model)


def random_state(rng, tree):
    """Angles over most of a turn, strokes of +-0.8 m (beyond the limits on purpose: the dynamics
    do not depend on them)."""
    pris = tree.jtype == PRISMATIC
    q = np.where(pris, rng.uniform(-0.8, 0.8, tree.n), rng.uniform(-3.0, 3.0, tree.n))
    return q, rng.normal(0, 1.5, tree.n), rng.normal(0, 4.0, tree.n), rng.normal(0, 100.0, tree.n)


def test_urdf_joint_types_limits_and_merging(setup):
    tree, model, _, _ = setup
    assert tree.dof_names == ["slew", "extend", "wrist_roll", "plunge", "shift", "spin", "sled_travel", "flap_hinge"]
    assert tree.jtype.dtype == np.int64
    np.testing.assert_array_equal(tree.jtype, [REVOLUTE, PRISMATIC, REVOLUTE, PRISMATIC, PRISMATIC, REVOLUTE,
                                               PRISMATIC, REVOLUTE])
    assert [tree.is_prismatic(n) for n in ("extend", "spin")] == [True, False]
    np.testing.assert_array_equal(tree.parent, [-1, 0, 1, 2, 0, 4, -1, 6])
    i = tree.index("extend")  # prismatic limits in metres, damping in N s/m
    assert (tree.lower[i], tree.upper[i], tree.damping[i]) == (-0.3, 0.6, 150.0)
    j = tree.index("spin")  # continuous: revolute without limits
    assert tree.jtype[j] == REVOLUTE and tree.lower[j] == -np.inf and tree.upper[j] == np.inf
    np.testing.assert_allclose(np.linalg.norm(tree.axis, axis=1), 1.0, rtol=1e-15)
    # the fixed-joint housing is merged into the wrist body; the base into the root
    assert tree.mass[tree.index("wrist_roll")] == pytest.approx(1.7 + 0.8)
    assert tree.link_frames["wrist_housing"][0] == tree.index("wrist_roll")
    assert tree.link_frames["tip"][0] == tree.index("plunge")
    assert tree.mass.sum() == pytest.approx(sum(i.mass for i in model.inertias[1:]))


def test_unsupported_joint_type_is_refused_by_name():
    text = URDF.read_text().replace('name="shift" type="prismatic"', 'name="shift" type="planar"')
    with pytest.raises(UrdfError, match=r"joint 'shift': type 'planar' is not supported"):
        load_urdf(text, from_string=True)
    text = URDF.read_text().replace('lower="-0.3" upper="0.6"', 'lower="0.6" upper="-0.3"')
    with pytest.raises(UrdfError, match=r"joint 'extend': limit lower 0.6 must be below upper -0.3"):
        load_urdf(text, from_string=True)


def test_link_poses_match_pinocchio(setup):
    """Every URDF link frame (moving, merged through fixed joints, behind prismatic joints)."""
    tree, model, data, pm = setup
    rbm = RigidBodyModel(tree)
    rng = np.random.default_rng(11)
    for _ in range(10):
        q = random_state(rng, tree)[0]
        pin.framesForwardKinematics(model, data, pm.q(q))
        for link in tree.link_frames:
            R, p = rbm.link_pose(q, link)
            ref = data.oMf[model.getFrameId(link)]
            np.testing.assert_allclose(R, ref.rotation, atol=1e-12)
            np.testing.assert_allclose(p, ref.translation, atol=1e-12)


def test_a_prismatic_joint_translates_its_body_along_the_world_axis(setup):
    """Direct check of the rule, independent of Pinocchio: moving a prismatic joint by d moves its
    body origin by d along its (world) axis and does not rotate it."""
    tree, _, _, _ = setup
    rbm = RigidBodyModel(tree)
    q = random_state(np.random.default_rng(2), tree)[0]
    for name in ("extend", "plunge", "shift", "sled_travel"):
        i = tree.index(name)
        R0, o0 = (x[i] for x in rbm.frames(q))
        ax = R0 @ tree.axis[i]
        q2 = q.copy()
        q2[i] += 0.25
        R1, o1 = (x[i] for x in rbm.frames(q2))
        np.testing.assert_allclose(R1, R0, atol=1e-15)
        np.testing.assert_allclose(o1 - o0, 0.25 * ax, atol=1e-14)


def close(actual, expected):
    np.testing.assert_allclose(actual, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


def test_dynamics_match_pinocchio(setup):
    """M(q), bias c(q, qd) + g(q), gravity g(q), inverse dynamics and forward dynamics (ABA) to 1e-9."""
    tree, model, data, pm = setup
    rbm = RigidBodyModel(tree)
    rng = np.random.default_rng(42)
    z = np.zeros(tree.n)
    for _ in range(25):
        q, v, a, tau = random_state(rng, tree)
        qp, vp = pm.q(q), pm.v(v)
        close(rbm.mass_matrix(q), pm.matrix(pin.crba(model, data, qp)))
        close(rbm.inverse_dynamics(q, v, z), pm.back(pin.rnea(model, data, qp, vp, np.zeros(model.nv))))
        close(rbm.inverse_dynamics(q, z, z), pm.back(pin.computeGeneralizedGravity(model, data, qp)))
        close(rbm.inverse_dynamics(q, v, a), pm.back(pin.rnea(model, data, qp, vp, pm.v(a))))
        close(rbm.forward_dynamics(q, v, tau), pm.back(pin.aba(model, data, qp, vp, pm.v(tau))))


def test_energies_match_pinocchio(setup):
    tree, model, data, pm = setup
    rbm = RigidBodyModel(tree)
    rng = np.random.default_rng(7)
    for _ in range(10):
        q, v, _, _ = random_state(rng, tree)
        assert rbm.kinetic_energy(q, v) == pytest.approx(pin.computeKineticEnergy(model, data, pm.q(q), pm.v(v)), rel=1e-9)
        assert rbm.potential_energy(q) == pytest.approx(pin.computePotentialEnergy(model, data, pm.q(q)), rel=1e-9, abs=1e-9)


def test_power_balance_with_prismatic_joints(setup):
    """Physics beyond the oracle: under joint forces tau (N m, N) and no damping, the motion
    qdd = FD(q, qd, tau) changes T + V at the rate qd . tau (W). The rate is taken along (qd, qdd)
    by a 5-point finite difference (truncation ~1e-11 here)."""
    tree, _, _, _ = setup
    rbm = RigidBodyModel(tree)
    rng = np.random.default_rng(5)
    for _ in range(5):
        q, v, _, tau = random_state(rng, tree)
        qdd = rbm.forward_dynamics(q, v, tau)

        def energy(s):
            qs = q + s * v + 0.5 * s * s * qdd
            return rbm.kinetic_energy(qs, v + s * qdd) + rbm.potential_energy(qs)

        h = 1e-5
        rate = (-energy(2 * h) + 8 * energy(h) - 8 * energy(-h) + energy(-2 * h)) / (12 * h)
        assert rate == pytest.approx(float(v @ tau), rel=1e-9)


@pytest.mark.parametrize("robot", ["hydrolek", "mars_nd", "harvester"])
def test_revolute_trees_give_bit_identical_results_with_and_without_jtype(plants, robot):
    """kinematics/crba/rnea may be called with or without the trailing ``jtype``: from Python, and in
    the compiled kernel (its ``rigid_body_refresh``, which a revolute tree reaches with ``jtype`` None
    and a tree with a prismatic joint with the joint types). On an all-revolute tree every route gives
    the same bits."""
    t = plants(robot).tree
    assert not t.jtype.any()
    tt = (t.parent, t.R_tree, t.p_tree, t.axis, t.com, t.inertia, t.mass, t.gravity)
    mod = kernel()

    def python_calls(q, qd, qdd, jtype):
        ws, tau = RigidBodyWorkspace(t.n), np.zeros(t.n)
        extra = () if jtype is None else (jtype,)
        rb.kinematics(*tt[:6], q, ws.Rw, ws.ow, ws.aw, ws.cw, ws.Iw, ws.tmp33, *extra)
        rb.crba(t.parent, t.mass, ws.ow, ws.aw, ws.cw, ws.Iw, ws.mc, ws.hc, ws.Ic, ws.M, *extra)
        rb.rnea(t.parent, t.mass, t.gravity, ws.ow, ws.aw, ws.cw, ws.Iw, qd, qdd, 1.0, ws.w, ws.dw, ws.ao, ws.F,
                ws.N, tau, *extra)
        return [ws.Rw, ws.ow, ws.cw, ws.Iw, ws.M, tau]

    def kernel_calls(q, qd, qdd, jtype):
        assert not qdd.any()            # the kernel's refresh evaluates the bias at zero acceleration
        arrays = TreeArrays(t.parent, t.R_tree, t.p_tree, t.axis, t.mass, t.com, t.inertia, t.gravity,
                            None if jtype is None else np.ascontiguousarray(jtype, dtype=np.int64))
        ws = make_workspace(t.n, 0)
        mod.rigid_body_refresh(arrays, q, qd, ws)
        return [ws.Rw, ws.ow, ws.cw, ws.Iw, ws.M, ws.bias]

    rng = np.random.default_rng(3)
    for _ in range(5):
        q, qd, qdd = rng.uniform(-3, 3, t.n), rng.normal(size=t.n), rng.normal(size=t.n)
        routes = [python_calls(q, qd, qdd, None), python_calls(q, qd, qdd, t.jtype)]
        zero = np.zeros(t.n)
        routes += [python_calls(q, qd, zero, None), kernel_calls(q, qd, zero, None), kernel_calls(q, qd, zero, t.jtype)]
        for a, b in ((0, 1), (2, 3), (2, 4)):
            for x, y in zip(routes[a], routes[b]):
                assert x.tobytes() == y.tobytes()


def test_prismatic_flags_change_the_dynamics(setup):
    """The joint types are used: the same tree read as all-revolute gives other dynamics (guards
    against jtype being silently ignored by the compiled functions)."""
    tree, _, _, _ = setup
    rng = np.random.default_rng(9)
    q, v, a, _ = random_state(rng, tree)
    mixed = RigidBodyModel(tree)
    import copy

    as_revolute = copy.copy(tree)
    as_revolute.jtype = np.zeros(tree.n, dtype=np.int64)
    rev = RigidBodyModel(as_revolute)
    assert not np.allclose(mixed.mass_matrix(q), rev.mass_matrix(q), rtol=1e-3)
    assert not np.allclose(mixed.inverse_dynamics(q, v, a), rev.inverse_dynamics(q, v, a), rtol=1e-3)
