"""Reference controllers, the parts (no emulator process): harvester kinematics against the URDF model,
the identified valve model against the emulator's own valve chain, the feedforward against the plant,
the PID's deadband measures, the trajectories."""

import math

import numpy as np
import pytest

from controllers.feedforward import JointFeedforward
from controllers.kinematics import HarvesterKinematics
from controllers.pid import JointPID, PidGains
from controllers.plant_local import LocalPlant
from controllers.trajectories import OperatorCommand, Sinusoid, TargetSequence, VelocityStroke, path_length
from controllers.valve_model import ValveModel
from sim_core.dynamics.rigid_body import RigidBodyModel
from sim_core.kernel import layout as KL
from sim_core.model.spec import load_robot


def test_harvester_kinematics_match_the_urdf_model_and_invert():
    spec = load_robot("harvester")
    kin = HarvesterKinematics(spec)
    rb = RigidBodyModel(spec.tree)
    assert (kin.l1, kin.l2) == (4.6, 4.0) and list(kin.boom_pivot) == [0.3, 0.0, 1.8]
    rng = np.random.default_rng(3)
    for _ in range(50):
        q = rng.uniform(kin.lower, kin.upper)
        full = np.r_[q, rng.uniform(-1.0, 1.0, 2)]          # the passive Hooke joints do not move stick_tip
        p = kin.forward(q)
        assert np.allclose(p, rb.link_pose(full, "stick_tip")[1], atol=1e-12)
        assert np.allclose(kin.inverse(p), q, atol=1e-9)     # the stick-below-boom branch covers the whole range
        J = kin.jacobian(q)
        h = 1e-6
        Jn = np.column_stack([(kin.forward(q + h * e) - kin.forward(q - h * e)) / (2 * h) for e in np.eye(3)])
        assert np.allclose(J, Jn, atol=1e-7)
        v = rng.normal(size=3)
        assert np.allclose(J @ kin.joint_rates(q, v), v)
    with pytest.raises(ValueError, match="out of the crane's reach"):
        kin.inverse([20.0, 0.0, 2.0])


def test_valve_model_is_the_emulators_valve_chain():
    """Steady spool position and edge flow of the emulator (kernel) equal the controller's identified model:
    spool within 0.5 % of stroke, flow Q_PA = g(u) f(p_S - p_HA) within 0.5 % (the kernel's laminar
    regularisation f differs from sqrt by (1 + (dp_tr/dp)^2)^(-1/4) - 1 < 0.3 % for dp > 1 MPa)."""
    spec = load_robot("harvester")
    vm = ValveModel(spec, "stick")
    assert vm.deadband_v == 1.2 and vm.u_sat == pytest.approx(10.0) and (vm.c1, vm.c2, vm.c3) == (0.25, 0.45, 0.30)
    a = spec.joint_names.index("stick")
    for u in (0.8, 2.0, 5.0, -3.0, 9.0):
        plant = LocalPlant("harvester", spec=spec, tick_s=1e-3)
        plant.start()
        cmd = np.zeros(3)
        cmd[a] = u
        for _ in range(150):       # 0.15 s: coil (4 ms) and spool (25 Hz) settled
            plant.exchange(cmd)
        XS = plant.ctx.XS
        assert XS[a, KL.XS_SPOOL_X] == pytest.approx(vm.spool(u), abs=5e-3)
        if abs(u) > vm.deadband_v:
            dp = plant.ctx.XG[KL.XG_P_S] - XS[a, KL.XS_PH_A] if u > 0 else XS[a, KL.XS_PH_A]
            assert dp > 1e6
            assert abs(XS[a, KL.XS_Q_A]) == pytest.approx(vm.conductance(u) * math.sqrt(dp), rel=5e-3)
        else:
            assert XS[a, KL.XS_Q_A] == 0.0
    for u in (1.25, 1.3, 2.0, 4.7, 9.99):        # the inverse of the characteristic
        assert vm.voltage_for_conductance(vm.conductance(u)) == pytest.approx(u, abs=1e-6)
    assert vm.voltage_for_conductance(0.0) == 0.0
    assert vm.voltage_for_conductance(10 * vm.kv) == vm.u_sat


@pytest.mark.parametrize("joint,speed", [("stick", 0.15), ("stick", -0.15), ("boom", 0.08), ("boom", -0.08)])
def test_feedforward_alone_gives_the_desired_speed(joint, speed):
    """Open loop, u = u_ff(q'_d, p_A, p_B) each 5 ms: the joint moves at q'_d within 5 %. The feedforward
    neglects the hose drop between valve and chamber (~0.1-0.3 MPa of ~10 MPa per edge at these flows:
    1-2 % of flow) and the orifice's laminar correction (< 0.3 %); 5 % leaves room for the gravity-load
    change over the 1 s average."""
    spec = load_robot("harvester")
    ff = JointFeedforward(spec, joint)
    a = spec.joint_names.index(joint)
    plant = LocalPlant("harvester", spec=spec, tick_s=1e-3, ticks=5)
    obs = plant.start()
    q_start = obs.angle[a]
    angles, times = [], []
    for _ in range(400):       # 2 s
        u = np.zeros(3)
        u[a] = ff.voltage(obs.angle[a], speed, obs.p_a[a], obs.p_b[a])
        obs = plant.exchange(u)
        angles.append(obs.angle[a])
        times.append(obs.t)
    t, q = np.array(times), np.array(angles)
    late = t > 1.0
    measured = np.polyfit(t[late], q[late], 1)[0]
    assert abs(q[-1] - q_start) > 0.1
    assert measured == pytest.approx(speed, rel=0.05)


def test_pid_deadband_measures():
    # deadband compensation is continuous at zero and adds the full width beyond the ramp
    g = PidGains(kp=100.0, deadband_comp=0.8, comp_ramp=0.2)
    pid = JointPID(g)
    pid.reset(0.0, 0.0)
    assert pid.update(0.005, 0.0, 1e-5).u == pytest.approx(1e-3 * (1 + 0.8 / 0.2))
    pid.reset(0.0, 0.0)
    assert pid.update(0.005, 0.0, -0.01).u == pytest.approx(-1.0 - 0.8)
    # settle band with hysteresis: neutral inside 3 mrad, back in control only beyond 10 mrad
    g = PidGains(kp=100.0, ki=50.0, settle_band=0.003, release_band=0.010, i_band=0.01)
    pid = JointPID(g)
    pid.reset(0.0, 0.0)
    t = 0.0
    for e, settled in ((0.02, False), (0.002, True), (0.008, True), (-0.009, True), (0.011, False), (0.005, False)):
        t += 0.005
        terms = pid.update(t, 0.0, e)
        assert terms.settled is settled
        assert (terms.u == 0.0) is settled
    assert pid.update(t + 0.005, 0.0, 0.005, qd_d=0.1).settled is False     # moving reference: never settled
    # conditioned integral: nothing outside i_band, clamped while saturated, limited to i_limit
    pid = JointPID(PidGains(kp=1.0, ki=10.0, i_band=0.05, i_limit=2.0))
    pid.reset(0.0, 0.0)
    pid.update(1.0, 0.0, 0.1)
    assert pid.integral == 0.0
    pid.update(2.0, 0.0, 0.04)
    assert pid.integral == pytest.approx(0.04)
    pid = JointPID(PidGains(kp=1000.0, ki=10.0))
    pid.reset(0.0, 0.0)
    for k in range(1, 5):
        pid.update(float(k), 0.0, 1.0)              # saturated at 10 V from the first step on
    assert pid.integral == pytest.approx(1.0)       # only the first step integrated
    pid = JointPID(PidGains(kp=0.0, ki=10.0, i_limit=2.0))
    pid.reset(0.0, 0.0)
    for k in range(1, 20):
        terms = pid.update(float(k), 0.0, 0.1)
    assert terms.i == pytest.approx(2.0)
    # velocity from the measured angle (filtered difference)
    pid = JointPID(PidGains(kp=0.0, kd=1.0, tau_d=0.0))
    pid.reset(0.0, 0.0)
    assert pid.update(0.01, 0.002, 0.0).d == pytest.approx(-0.2)


def test_trajectories():
    s = Sinusoid(-1.3, 0.25, 10.0)
    assert s(0.0) == (-1.3, 0.0) and s(5.0)[0] == pytest.approx(-0.8) and s(2.5)[1] == pytest.approx(0.25 * 2 * math.pi / 10)
    op = OperatorCommand([VelocityStroke(0.5, 6.0, (-1.8, 0.0, 1.1)), VelocityStroke(3.0, 4.0, (0.0, 2.0, 0.0))])
    ts, ps = op.path([1.0, 2.0, 3.0], 0.001)
    assert np.allclose(ps[-1], [1.0 - 1.8, 2.0 + 2.0, 3.0 + 1.1], atol=1e-5)   # strokes integrate to their displacements
    assert np.allclose(op.velocity(0.0), 0.0) and np.allclose(op.velocity(op.duration), 0.0, atol=1e-12)
    assert path_length(np.array([[0, 0, 0], [3, 4, 0], [3, 4, 1]])) == 6.0
    seq = TargetSequence(np.zeros(2), [[0.1, -0.2], [0.0, 0.0]], move_time=2.0, hold_time=3.0)
    assert seq.duration == 10.0
    q, qd = seq(1.0)
    assert np.allclose(q, [0.05, -0.1]) and qd[0] > 0
    q, qd = seq(4.9)
    assert np.allclose(q, [0.1, -0.2]) and np.all(qd == 0.0)
    q, qd = seq(7.0)
    assert np.allclose(q, 0.0) and np.all(qd == 0.0)
