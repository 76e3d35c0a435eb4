"""Rigid-body dynamics against Pinocchio (test-time oracle) and the paper's Table 1."""

import numpy as np
import pinocchio as pin
import pytest

from sim_core.dynamics.rigid_body import RigidBodyModel
from sim_core.model.urdf import load_urdf

ROBOTS = ["hydrolek", "mars_nd", "harvester"]

# Montazeri & Ekotuyo, Table 1: link offsets in mm (x, y, z), paper frame
TABLE1_MM = [(80, 0, 0), (137.29, 35.36, -32.01), (413.25, 301.53, 0), (161, -84.85, 0),
             (44.45, -129.3, 0), (18.45, 278.05, 0), (150, 0, 0)]


@pytest.mark.parametrize("robot", ROBOTS)
def test_dynamics_match_pinocchio(plants, robot):
    plant = plants(robot)
    tree = plant.tree
    rb = RigidBodyModel(tree)
    model = pin.buildModelFromUrdf(str(plant.spec.urdf_path))
    data = model.createData()
    idx = [model.joints[model.getJointId(n)].idx_q for n in tree.dof_names]
    assert model.nq == tree.n
    rng = np.random.default_rng(42)
    for _ in range(25):
        q = rng.uniform(-2.0, 2.0, tree.n)
        v = rng.normal(0, 1.0, tree.n)
        a = rng.normal(0, 3.0, tree.n)
        tau = rng.normal(0, 200.0, tree.n)
        qp, vp, ap, tp = (np.zeros(model.nv) for _ in range(4))
        qp[idx], vp[idx], ap[idx], tp[idx] = q, v, a, tau
        t_ref = pin.rnea(model, data, qp, vp, ap)[idx]
        np.testing.assert_allclose(rb.inverse_dynamics(q, v, a), t_ref, rtol=1e-9, atol=1e-9 * np.abs(t_ref).max())
        M_ref = pin.crba(model, data, qp)
        M_ref = (np.triu(M_ref) + np.triu(M_ref, 1).T)[np.ix_(idx, idx)]
        np.testing.assert_allclose(rb.mass_matrix(q), M_ref, rtol=1e-9, atol=1e-9 * np.abs(M_ref).max())
        a_ref = pin.aba(model, data, qp, vp, tp)[idx]
        np.testing.assert_allclose(rb.forward_dynamics(q, v, tau), a_ref, rtol=1e-9, atol=1e-9 * np.abs(a_ref).max())


@pytest.mark.parametrize("robot", ROBOTS)
def test_potential_and_kinetic_energy_match_pinocchio(plants, robot):
    plant = plants(robot)
    rb = RigidBodyModel(plant.tree)
    model = pin.buildModelFromUrdf(str(plant.spec.urdf_path))
    data = model.createData()
    idx = [model.joints[model.getJointId(n)].idx_q for n in plant.tree.dof_names]
    rng = np.random.default_rng(7)
    q, v = rng.uniform(-1, 1, plant.tree.n), rng.normal(size=plant.tree.n)
    qp, vp = np.zeros(model.nq), np.zeros(model.nv)
    qp[idx], vp[idx] = q, v
    assert rb.kinetic_energy(q, v) == pytest.approx(pin.computeKineticEnergy(model, data, qp, vp), rel=1e-9)
    # Pinocchio's potential is -sum m g.c, like ours
    assert rb.potential_energy(q) == pytest.approx(pin.computePotentialEnergy(model, data, qp), rel=1e-9, abs=1e-9)


def test_forward_kinematics_reproduces_table1_at_zero_pose(plants):
    """Joint origins at the zero pose, expressed in the arm's base frame, step by Table 1's offsets."""
    plant = plants("hydrolek")
    rb = RigidBodyModel(plant.tree)
    q = np.zeros(plant.tree.n)
    R_base, p_base = rb.link_pose(q, "base_link")
    origins = [p_base]
    Rw, ow = rb.frames(q)
    origins += [ow[plant.tree.index(f"j{k}")] for k in range(1, 8)]
    for k in range(7):
        offset = R_base.T @ (origins[k + 1] - origins[k])  # in the paper's (base) frame
        np.testing.assert_allclose(offset * 1000.0, TABLE1_MM[k], atol=1e-9)


def test_mars_nd_arms_are_the_hydrolek_arm(plants):
    """The dual-arm URDF carries two exact copies of the HydroLek arm (prefixed)."""
    single = load_urdf(plants("hydrolek").spec.urdf_path)
    dual = plants("mars_nd").tree
    for prefix in ("left_", "right_"):
        for k, name in enumerate(single.dof_names):
            i = dual.index(prefix + name)
            np.testing.assert_allclose(dual.p_tree[i] if k else dual.p_tree[i] * 0, single.p_tree[k] if k else single.p_tree[k] * 0)
            np.testing.assert_allclose(dual.axis[i], single.axis[k])
            assert dual.mass[i] == pytest.approx(single.mass[k])
            np.testing.assert_allclose(dual.inertia[i], single.inertia[k], atol=1e-12)
            assert (dual.lower[i], dual.upper[i]) == (single.lower[k], single.upper[k])
