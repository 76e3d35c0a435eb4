"""Each effect of the bank changes the simulated output the way its docstring says."""

import math

import numpy as np
import pytest
from scipy.signal import detrend, welch

from sim_core.components.cylinder import cylinder_length
from sim_core.components.pump import P_S
from sim_core.effects import EFFECTS
from sim_core.kernel import layout as L
from sim_core.simulator import Simulator

from helpers import run_joint, step


@pytest.fixture(scope="module")
def arm(plants):
    return plants("hydrolek")


def moved(q):
    return q[-1] - q[0]


def test_every_effect_is_covered():
    tested = {n[len("test_"):] for n in globals() if n.startswith("test_") and n[len("test_"):] in EFFECTS}
    assert tested == set(EFFECTS)


def test_deadband(arm):
    eff = [("deadband", "j2", {"width": 1.0})]
    for v in (0.5, 0.95):   # below the width: no motion at all, where the nominal valve moves the joint
        assert moved(run_joint(arm, "j2", step(v), effects=eff)[1]) == 0.0
        assert moved(run_joint(arm, "j2", step(v))[1]) > 0.01
    # above: the valve acts as if commanded |u| - w
    q_db = moved(run_joint(arm, "j2", step(3.0), effects=eff)[1])
    q_eq = moved(run_joint(arm, "j2", step(2.0))[1])
    assert q_db == pytest.approx(q_eq, rel=0.02)


def test_valve_offset(arm):
    eff = [("valve_offset", "j2", {"offset": 0.5})]
    const = lambda v: (lambda t: np.full_like(t, v))
    # at zero command the joint creeps exactly as a nominal valve commanded with the offset
    q0 = run_joint(arm, "j2", const(0.0), effects=eff)[1]
    np.testing.assert_array_equal(q0, run_joint(arm, "j2", const(0.5))[1])
    assert moved(q0) > 0.01
    # commanding minus the offset holds the joint as a nominal valve at zero command does
    np.testing.assert_array_equal(run_joint(arm, "j2", const(-0.5), effects=eff)[1], run_joint(arm, "j2", const(0.0))[1])
    # the offset shifts the command before the spool overlap: with a 1 V deadband, +0.6 V (1.1 V at the
    # spool) moves the joint and -0.6 V (-0.1 V) does not
    both = eff + [("deadband", "j2", {"width": 1.0})]
    assert moved(run_joint(arm, "j2", step(0.6), effects=both)[1]) > 0.01 * moved(run_joint(arm, "j2", step(0.6))[1])
    assert moved(run_joint(arm, "j2", step(-0.6), effects=both)[1]) == 0.0


def test_hysteresis(arm):
    pulse = step(4.0, 0.2, 0.7)
    q = run_joint(arm, "j2", pulse, effects=[("hysteresis", "j2", {"width": 0.8})], T=4.0)[1]
    qn = run_joint(arm, "j2", pulse, T=4.0)[1]
    creep = q[-1] - q[1500]                      # after the command returned to 0 V
    assert creep > 0.01                           # keeps moving in the previous direction
    assert abs(qn[-1] - qn[1500]) < 1e-6
    # the creep speed is that of a 0.4 V (half-width) command
    q04 = run_joint(arm, "j2", lambda t: np.full_like(t, 0.4), T=4.0)[1]
    assert creep / 2.5 == pytest.approx((q04[-1] - q04[1500]) / 2.5, rel=0.05)


def test_delay(arm):
    t, q, _, _ = run_joint(arm, "j2", step(4.0), effects=[("delay", "j2", {"delay": 0.05})])
    qn = run_joint(arm, "j2", step(4.0))[1]
    # same response, 50 ms later
    np.testing.assert_allclose(q[300:1500], qn[250:1450], atol=2e-4)
    assert np.abs(q[300:1500] - qn[300:1500]).max() > 5e-3


def test_spool_lag(arm):
    q = run_joint(arm, "j2", step(4.0), effects=[("spool_lag", "j2", {"time_constant": 0.1})])[1]
    qn = run_joint(arm, "j2", step(4.0))[1]
    assert moved(q[:300]) < 0.5 * moved(qn[:300])          # starts later (0.1 s after the step)
    speed = (q[1100] - q[900]) / (qn[1100] - qn[900])       # same steady speed once the lag has passed
    assert speed == pytest.approx(1.0, abs=0.01)


def test_valve_asymmetry(arm):
    neg = lambda t: np.where((t > 0.2) & (t < 1.5), -4.0, 0.0)
    q = run_joint(arm, "j2", neg, effects=[("valve_asymmetry", "j2", {"ratio": 0.7})])[1]
    qn = run_joint(arm, "j2", neg)[1]
    assert (q[1400] - q[900]) / (qn[1400] - qn[900]) == pytest.approx(0.7, rel=0.02)
    pos = run_joint(arm, "j2", step(4.0), effects=[("valve_asymmetry", "j2", {"ratio": 0.7})])[1]
    # positive travel unchanged (only the spool's brief undershoot at the stop meets the slower edges)
    assert moved(pos) == pytest.approx(moved(run_joint(arm, "j2", step(4.0))[1]), rel=1e-3)


def test_leakage(arm):
    eff = [("leakage", "j2", {"internal": 5e-12, "external": 1e-12})]
    t, q, tr, _ = run_joint(arm, "j2", lambda t: 0 * t, effects=eff, T=5.0)
    qn = run_joint(arm, "j2", lambda t: 0 * t, T=5.0)[1]
    assert abs(moved(q)) > 0.02 and moved(qn) == 0.0       # valve closed, yet the loaded joint drifts
    assert abs(q[-1] - q[-1001]) > 1e-3                     # and keeps drifting
    dp = tr.pressure("j2", "a") - tr.pressure("j2", "b")
    assert abs(dp[-1] - dp[0]) > 1e6                        # the chamber pressures redistribute as oil leaks


def test_coulomb_friction(arm):
    eff = [("coulomb_friction", "j2", {"torque": 100.0})]
    t, q, tr, ctx = run_joint(arm, "j2", step(4.0), effects=eff)
    _, qn, trn, _ = run_joint(arm, "j2", step(4.0))
    a = arm.joint_names.index("j2")
    AP = ctx.AP

    def force(traj, k):
        pa, pb = traj.pressure("j2", "a")[k], traj.pressure("j2", "b")[k]
        arm_len = cylinder_length(traj.q[k, 1], AP[a, L.AP_LK_C0], AP[a, L.AP_LK_D1], AP[a, L.AP_LK_D2])[1]
        return (pa * AP[a, L.AP_AREA_A] - pb * AP[a, L.AP_AREA_B]) * arm_len
    # while moving up at steady speed the actuator torque carries 100 N m of friction more
    extra = np.mean([force(tr, k) - force(trn, k) for k in range(800, 1100)])
    assert extra == pytest.approx(100.0, rel=0.05)
    assert moved(q) < moved(qn)                             # load-sensitive orifice flow: slightly slower


def test_backlash(arm):
    t, q, tr, _ = run_joint(arm, "j2", lambda t: np.where(t < 1.0, 4.0, -4.0) * (t > 0.1),
                            effects=[("backlash", "j2", {"width": 0.02})], T=2.0)
    err = tr.angle("j2") - q
    assert err[900] == pytest.approx(-0.01, abs=5e-4)      # lags by b/2 while moving up
    assert err[1900] == pytest.approx(+0.01, abs=5e-4)     # and by b/2 the other way moving down


def test_area_ratio(arm):
    neg = lambda t: np.where((t > 0.2) & (t < 1.5), -4.0, 0.0)
    eff = [("area_ratio", "j2", {"ratio": 0.55})]
    t, q, tr, _ = run_joint(arm, "j2", neg, effects=eff)
    _, qn, trn, _ = run_joint(arm, "j2", neg)
    assert abs(moved(q) / moved(qn) - 1.0) > 0.03            # retraction speed changes
    # in the hold the rod-side pressure rises: the same load on a smaller annulus
    assert tr.pressure("j2", "b")[100] > trn.pressure("j2", "b")[100] + 5e5


def test_flow_saturation(arm):
    eff = [("flow_saturation", "j2", {"max_flow": 3e-5})]
    small = run_joint(arm, "j2", step(2.0), effects=eff)[1]
    assert moved(small) == pytest.approx(moved(run_joint(arm, "j2", step(2.0))[1]), rel=1e-6)
    s6 = run_joint(arm, "j2", step(6.0), effects=eff)[1]
    s9 = run_joint(arm, "j2", step(9.0), effects=eff)[1]
    assert moved(s9) == pytest.approx(moved(s6), rel=0.02)   # speed no longer grows with the command
    assert moved(s9) < 0.8 * moved(run_joint(arm, "j2", step(9.0))[1])


def test_pump_limit(arm):
    """Beyond the pump's flow the speed stops growing with the command; the supply sags while the valve
    asks for more and recovers once it closes; the line's oil gives a surge that an instantaneous
    flow cap (flow_saturation) does not."""
    eff = [("pump_limit", None, {"max_flow": 3e-5})]
    small = moved(run_joint(arm, "j2", step(1.0), effects=eff)[1])
    assert small == pytest.approx(moved(run_joint(arm, "j2", step(1.0))[1]), rel=0.02)
    late = lambda q: q[1100] - q[700]        # steady: the line's oil spent, the pump's flow is all there is
    s6 = run_joint(arm, "j2", step(6.0), effects=eff)[1]
    s9 = run_joint(arm, "j2", step(9.0), effects=eff)[1]
    assert late(s9) == pytest.approx(late(s6), rel=0.03)      # speed no longer grows with the command
    assert late(s9) < 0.6 * late(run_joint(arm, "j2", step(9.0))[1])
    # the first 0.2 s after the valve opens: the line's stored oil moves the joint further than a cap of
    # the same flow lets it
    early = lambda q: q[400] - q[200]
    capped = run_joint(arm, "j2", step(9.0), effects=[("flow_saturation", "j2", {"max_flow": 3e-5})])[1]
    assert early(s9) > 1.3 * early(capped)
    # the supply node: at its setting at rest, far below it while the valve is open, back after
    spec = arm.spec.copy()
    spec.enable_effect("pump_limit", None, max_flow=3e-5)
    ctx = arm.create_context(spec)
    sim, u, a = Simulator(ctx), np.zeros(len(arm.joint_names)), arm.joint_names.index("j2")
    p_set, ps = spec.supply["pressure"], []
    for k in range(1500):
        u[a] = 9.0 if 200 <= k < 700 else 0.0
        sim.step(u, 1e-3)
        ps.append(ctx.XG[P_S])
    assert ps[150] == pytest.approx(p_set, rel=1e-3)
    assert min(ps[200:700]) < 0.7 * p_set
    assert ps[-1] > 0.97 * p_set


def test_line_dynamics(plants):
    """Harvester stick: a valve step rings the hose at its L-C frequency, seen in the valve-end pressure."""
    H = plants("harvester")
    spec = H.spec.copy()
    ctx = H.create_context(spec)
    a = H.joint_names.index("stick")
    sim = Simulator(ctx)
    dt = 1e-4
    n = int(1.0 / dt)
    dp = np.zeros(n)
    u = np.zeros(3)
    for k in range(n):
        u[a] = 6.0 if k * dt >= 0.5 else 0.0
        sim.step(u, dt)
        dp[k] = ctx.XS[a, L.XS_PH_A] - ctx.XS[a, L.XS_P_A]
    f, P = welch(detrend(dp[n // 2:]), fs=1 / dt, nperseg=2048)
    band = (f > 5) & (f < 500)
    f_peak = f[band][np.argmax(P[band])]
    AP = ctx.AP
    L_, _ = cylinder_length(ctx.q[2], AP[a, L.AP_LK_C0], AP[a, L.AP_LK_D1], AP[a, L.AP_LK_D2])
    Cc = (AP[a, L.AP_VDEAD_A] + AP[a, L.AP_AREA_A] * (L_ - AP[a, L.AP_LK_LMIN])) / ctx.GP[L.GP_BETA]
    Ch = AP[a, L.AP_HOSE_VOL] / AP[a, L.AP_HOSE_BETA]
    f_lc = math.sqrt((1 / Ch + 1 / Cc) / AP[a, L.AP_HOSE_I]) / (2 * math.pi)
    assert f_peak == pytest.approx(f_lc, rel=0.25)
    # switched off, the hose is a lumped volume: no pressure difference along it
    ctx.disable_effect("line_dynamics", "stick")
    for k in range(2000):
        sim.step(u, dt)
    assert ctx.XS[a, L.XS_PH_A] == ctx.XS[a, L.XS_P_A]


def test_joint_compliance(arm):
    t, q, tr, _ = run_joint(arm, "j2", step(6.0), effects=[("joint_compliance", "j2", {"frequency": 4.0, "damping_ratio": 0.05})])
    f, P = welch(detrend(tr.pressure("j2", "a")[t >= 1.2]), fs=1000.0, nperseg=1024)
    band = (f > 1.5) & (f < 50)
    assert f[band][np.argmax(P[band])] == pytest.approx(4.0, rel=0.25)
    t, qn, trn, _ = run_joint(arm, "j2", step(6.0))
    assert np.ptp(q[t >= 1.3]) > 3 * np.ptp(qn[t >= 1.3])     # the link rings after it stops


def test_payload(arm):
    spec = arm.spec.copy()
    base = arm.create_context(spec)
    spec.enable_effect("payload", "j6", mass=10.0)
    loaded = arm.create_context(spec)
    # holding the arm needs 10 kg * g more at the tool: the shoulder's torque grows by m g r
    g0 = base.rigid_body().inverse_dynamics(base.q, np.zeros(7), np.zeros(7))
    g1 = loaded.rigid_body().inverse_dynamics(loaded.q, np.zeros(7), np.zeros(7))
    rb = base.rigid_body()
    R, p_tool = rb.link_pose(base.q, "tool")
    _, o2 = rb.frames(base.q)
    r = p_tool - o2[1]
    axis = rb.frames(base.q)[0][1] @ arm.tree.axis[1]
    expected = np.dot(axis, np.cross(r, np.array([0, 0, 10.0 * 9.81])))
    assert g1[1] - g0[1] == pytest.approx(expected, rel=1e-9)
    # lifting slows, lowering speeds up
    up = moved(run_joint(arm, "j2", step(3.0), ctx=loaded)[1])
    assert up < moved(run_joint(arm, "j2", step(3.0), ctx=arm.create_context())[1])
    loaded2 = arm.create_context(spec)
    down = moved(run_joint(arm, "j2", step(-3.0), ctx=loaded2)[1])
    assert down < moved(run_joint(arm, "j2", step(-3.0), ctx=arm.create_context())[1])


def test_sensor_offset(arm):
    t, q, tr, _ = run_joint(arm, "j2", step(4.0), effects=[("sensor_offset", "j2", {"offset": 0.03})])
    err = tr.angle("j2") - q
    noise = arm.spec.joint("j2").components["sensor"]["noise"] * abs(arm.spec.joint("j2").components["sensor"]["A"])
    assert np.mean(err) == pytest.approx(0.03, abs=3 * noise / math.sqrt(err.size) + 1e-4)
    assert np.std(err) < 3 * noise                         # constant, in holds and in motion


def test_sensor_gain(arm):
    t, q, tr, _ = run_joint(arm, "j3", step(4.0), effects=[("sensor_gain", "j3", {"gain": 1.05})])
    ratio = tr.angle("j3") / q
    sel = np.abs(q) > 0.2
    assert np.median(ratio[sel]) == pytest.approx(1.05, abs=2e-3)


def test_bulk_modulus(arm):
    """Entrained air softens the hydraulic spring: a locked, loaded joint sags by 1/(beta_e/beta) more."""
    sags = []
    for on in (False, True):
        spec = arm.spec.copy()
        if on:
            spec.enable_effect("bulk_modulus", None, scale=0.3, air_pressure=1e6)
        ctx = arm.create_context(spec)
        mid = 0.5 * (ctx.GP[L.GP_P_SUPPLY] + ctx.GP[L.GP_P_TANK])
        ctx.XS[:, L.XS_P_A] = ctx.XS[:, L.XS_PH_A] = mid      # unbalanced: the chambers must compress
        ctx.XS[:, L.XS_P_B] = ctx.XS[:, L.XS_PH_B] = mid
        q0 = ctx.q[1]
        t = np.arange(0, 4.0, 1e-3)
        traj = Simulator(ctx).run(t, np.zeros((t.size, 7)))
        sags.append(traj.q[-1000:, 1].mean() - q0)
        pa, pb = ctx.XS[1, L.XS_P_A], ctx.XS[1, L.XS_P_B]
    factor = np.mean([0.3 / (1 + 1e6 / (p + ctx.GP[L.GP_P_ATM])) for p in (pa, pb)])
    assert abs(sags[0]) > 1e-4
    assert sags[1] / sags[0] == pytest.approx(1.0 / factor, rel=0.1)


def test_stribeck_friction(arm):
    """Friction holds up to the static level until the joint breaks free, then falls to Coulomb's."""
    ts, tc, vs = 300.0, 100.0, 0.01
    eff = [("stribeck_friction", "j2", {"static_torque": ts, "coulomb_torque": tc, "stribeck_velocity": vs})]
    ramp = lambda t: np.clip((t - 0.2) * 2.0, 0.0, 4.0)   # the valve opens slowly: pressure builds up first
    t, q, tr, ctx = run_joint(arm, "j2", ramp, effects=eff)
    _, qn, trn, _ = run_joint(arm, "j2", ramp)
    a = arm.joint_names.index("j2")
    AP = ctx.AP

    def force(traj):
        pa, pb = traj.pressure("j2", "a"), traj.pressure("j2", "b")
        arm_len = np.array([cylinder_length(x, AP[a, L.AP_LK_C0], AP[a, L.AP_LK_D1], AP[a, L.AP_LK_D2])[1]
                            for x in traj.q[:, 1]])
        return (pa * AP[a, L.AP_AREA_A] - pb * AP[a, L.AP_AREA_B]) * arm_len

    extra = force(tr) - force(trn)
    free = np.argmax(tr.qd[:, 1] > vs)                      # the joint breaks free
    assert 0.8 * ts < extra[:free].max() < 1.05 * ts        # held by up to the static friction
    assert np.mean(extra[2500:2800]) == pytest.approx(tc, rel=0.05)   # sliding fast: the Coulomb level
    assert np.mean(tr.qd[2500:2800, 1]) > 10 * vs
