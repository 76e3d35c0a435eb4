"""Component equations against their closed forms, and spec validation."""

import math

import numpy as np
import pytest
from scipy.linalg import expm

from sim_core.components.cylinder import cylinder_length
from sim_core.components.directional_valve import opening, orifice
from sim_core.components.spool import discretise
from sim_core.model.spec import SpecError, load_robot


def test_orifice_is_turbulent_far_from_zero_and_laminar_near_it():
    tr = 1e5
    for dp in (1e7, 3e6, -5e6):
        f, _ = orifice(dp, tr)
        # regularisation error of the turbulent law falls off as (dp_tr/dp)^2 / 4
        assert f == pytest.approx(math.copysign(math.sqrt(abs(dp)), dp), rel=0.26 * (tr / dp) ** 2)
    f0, s0 = orifice(0.0, tr)
    assert f0 == 0.0 and s0 == pytest.approx(1.0 / math.sqrt(tr))   # finite laminar slope
    for dp in (-2e5, -1e3, 0.0, 5e4, 7e6):
        h = 1e-3 * max(abs(dp), 1e3)
        num = (orifice(dp + h, tr)[0] - orifice(dp - h, tr)[0]) / (2 * h)
        assert orifice(dp, tr)[1] == pytest.approx(num, rel=1e-6)
        assert orifice(-dp, tr)[0] == pytest.approx(-orifice(dp, tr)[0])


def test_opening_characteristic():
    assert opening(0.05, 0.1, 1.0, 0.0, 0.0) == 0.0          # inside the overlap
    assert opening(1.0, 0.1, 0.25, 0.45, 0.3) == pytest.approx(1.0)
    s = np.linspace(0, 1, 50)
    a = [opening(x, 0.0, 0.25, 0.45, 0.3) for x in s]
    assert np.all(np.diff(a) >= 0)
    assert opening(0.5, 0.0, 0.25, 0.45, 0.3) < 0.5              # progressive (harvester fit)


def test_command_chain_discretisation_matches_scipy_expm():
    tau, f, zeta, gain, lag, h = 0.008, 15.0, 0.8, 1.25, 0.05, 2.5e-4
    wn = 2 * math.pi * f
    phi, gam = discretise(tau, wn, zeta, gain, lag, h)
    A = np.zeros((5, 5))
    B = np.zeros((5, 2))
    A[0, 0] = A[1, 1] = -1 / tau
    B[0, 0] = B[1, 1] = 1 / tau
    A[2, 3] = 1
    A[3, :4] = [wn**2 * gain, -wn**2 * gain, -wn**2, -2 * zeta * wn]
    A[4, 2], A[4, 4] = 1 / lag, -1 / lag
    Maug = np.zeros((7, 7))
    Maug[:5, :5], Maug[:5, 5:] = A, B
    E = expm(Maug * h)
    np.testing.assert_allclose(phi, E[:5, :5], atol=1e-13)
    np.testing.assert_allclose(gam, E[:5, 5:], atol=1e-13)
    # steady state: full current difference -> spool at gain * i
    phi_l, gam_l = discretise(tau, wn, zeta, gain, lag, 10.0)
    z = phi_l @ np.zeros(5) + gam_l @ np.array([0.8, 0.0])
    assert z[2] == pytest.approx(1.0, rel=1e-9) and z[4] == pytest.approx(1.0, rel=1e-9)


@pytest.mark.parametrize("h", [2.4e-4, 1.9e-4, 2.6e-4, 3.6e-4])
def test_command_chain_for_another_substep_is_exact(h):
    """A substep other than the first is reached from the base one (Phi0 e^{A d}, Gam0 + Phi0 Gam(d)):
    the result equals scipy's exponential at that substep to rounding, for shorter and longer ones,
    and the stiff spool (300 Hz) included; an actuator with the same chain as an earlier one shares
    its matrices, one with another chain does not."""
    from sim_core.components.spool import (CMD_H, CMD_H0, GAM, LAG_TAU, PHI, SOL_TAU, SPOOL_GAIN,
                                           SPOOL_WN, SPOOL_ZETA, command_chain_matrix, refresh_command_chain)
    from sim_core.kernel import layout as L

    AP = np.zeros((4, L.AP_N))
    chains = [(4e-3, 25.0, 0.8, 0.667, 0.01), (2e-3, 300.0, 0.2, 5.0, 1e-3), (4e-3, 25.0, 0.8, 0.667, 0.01),
              (4e-3, 25.0, 0.8, 0.667, 0.02)]
    for a, (tau, fn, zeta, gain, lag) in enumerate(chains):
        AP[a, SOL_TAU], AP[a, SPOOL_WN], AP[a, SPOOL_ZETA] = tau, 2 * math.pi * fn, zeta
        AP[a, SPOOL_GAIN], AP[a, LAG_TAU], AP[a, CMD_H], AP[a, CMD_H0] = gain, lag, -1.0, -1.0
    Acc, Bcc, work = np.zeros((5, 5)), np.zeros((5, 2)), np.zeros((6, 7, 7))
    refresh_command_chain(AP, 2.5e-4, Acc, Bcc, work)
    refresh_command_chain(AP, h, Acc, Bcc, work)
    for a in range(4):
        assert AP[a, CMD_H0] == 2.5e-4 and AP[a, CMD_H] == h
        A, B = np.zeros((5, 5)), np.zeros((5, 2))
        command_chain_matrix(AP[a, SOL_TAU], AP[a, SPOOL_WN], AP[a, SPOOL_ZETA], AP[a, SPOOL_GAIN], AP[a, LAG_TAU], A, B)
        M = np.zeros((7, 7))
        M[:5, :5], M[:5, 5:] = A * h, B * h
        E = expm(M)
        np.testing.assert_allclose(AP[a, PHI:PHI + 25].reshape(5, 5), E[:5, :5], rtol=0, atol=1e-13 * np.abs(E[:5, :5]).max())
        np.testing.assert_allclose(AP[a, GAM:GAM + 10].reshape(5, 2), E[:5, 5:], rtol=0, atol=1e-13 * np.abs(E[:5, 5:]).max())


def _rodrigues(axis, q):
    """Rotation matrix about unit ``axis`` by ``q`` rad (independent of the kernel's)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(q) * k + (1.0 - np.cos(q)) * (k @ k)


@pytest.mark.parametrize("joint", ["j1", "j2", "j3", "j4", "j5"])
def test_cylinder_length_and_moment_arm_follow_the_mount_geometry(plants, joint):
    plant = plants("hydrolek")
    js = plant.spec.joint(joint)
    i = plant.tree.index(js.dof)
    cyl = js.components["cylinder"]
    c0, d1, d2, lmin, stroke = cyl.linkage(plant.tree.axis[i], plant.tree.lower[i], plant.tree.upper[i])
    for q in np.linspace(plant.tree.lower[i], plant.tree.upper[i], 9):
        R = _rodrigues(plant.tree.axis[i], q)
        direct = np.linalg.norm(R @ np.array(cyl["rod_mount"]) - np.array(cyl["base_mount"]))
        L, arm = cylinder_length(q, c0, d1, d2)
        assert L == pytest.approx(direct, rel=1e-12)
        num = (cylinder_length(q + 1e-6, c0, d1, d2)[0] - cylinder_length(q - 1e-6, c0, d1, d2)[0]) / 2e-6
        assert arm == pytest.approx(num, rel=1e-6) and arm > 0
    assert cylinder_length(plant.tree.lower[i], c0, d1, d2)[0] == pytest.approx(lmin)
    assert cylinder_length(plant.tree.upper[i], c0, d1, d2)[0] == pytest.approx(lmin + stroke)


def test_spec_errors_name_the_parameter():
    spec = load_robot("hydrolek")
    with pytest.raises(SpecError, match="joints.j2.valve.rated_flow"):
        spec.set("joints.j2.valve.rated_flow", -1.0)
    with pytest.raises(SpecError, match="unknown joint 'j9'"):
        spec.set("joints.j9.valve.rated_flow", 1e-5)
    with pytest.raises(SpecError, match="no 'cylinder' section"):
        spec.set("joints.j6.cylinder.bore", 0.05)
    with pytest.raises(SpecError, match="bore"):
        spec.set("joints.j2.cylinder.bore", float("nan"))
    # a mount that makes positive motion retract the cylinder is refused
    with pytest.raises(SpecError, match="extend the cylinder"):
        spec.set("joints.j2.cylinder.rod_mount", [-0.06059, -0.04421, 0.0])
    with pytest.raises(SpecError, match="unknown effect"):
        spec.enable_effect("warp_drive", "j2")
    with pytest.raises(SpecError, match="width"):
        spec.enable_effect("deadband", "j2", width=99.0)
    with pytest.raises(SpecError, match="global effect"):
        spec.enable_effect("bulk_modulus", "j2")
    with pytest.raises(SpecError, match="applies to cylinder"):
        spec.enable_effect("area_ratio", "j6", ratio=0.5)
    with pytest.raises(SpecError, match="no sensor"):
        spec.enable_effect("sensor_offset", "j6", offset=0.1)


def test_the_links_mass_scale_scales_every_mass_inertia_and_gravity_torque():
    from sim_core.lowering import initial_positions, lower
    from sim_core.dynamics.rigid_body import RigidBodyModel

    spec = load_robot("hydrolek")
    a = lower(spec)
    spec.set("links.mass_scale", 1.2)
    b = lower(spec)
    assert np.allclose(b.mass, 1.2 * a.mass) and np.allclose(b.inertia, 1.2 * a.inertia)
    assert np.array_equal(b.com, a.com)
    q, z = initial_positions(spec) + 0.3, np.zeros(spec.tree.n)
    ga = RigidBodyModel(spec.tree, a.mass, a.com, a.inertia).inverse_dynamics(q, z, z)
    gb = RigidBodyModel(spec.tree, b.mass, b.com, b.inertia).inverse_dynamics(q, z, z)
    assert np.allclose(gb, 1.2 * ga) and np.abs(ga).max() > 1.0
    with pytest.raises(SpecError, match="links.mass_scale"):
        spec.set("links.mass_scale", 9.0)

