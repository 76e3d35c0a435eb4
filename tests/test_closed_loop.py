"""Closed-loop records are recognised (the command follows the position reading), open-loop ones are
not, and diagnose says so in diagnosis.json and the report."""

import json

import numpy as np
import pytest

from sim_core.dataset import write_csv
from sim_core.identification import output_error as oe
from sim_core.identification.closed_loop import (CORRELATION_LIMIT, RESTART_TAUS, increments_evidence, joint_evidence,
                                                 time_constant)
from sim_core.identification.record import Record
from sim_core.kernel import layout as L
from sim_core.model.spec import load_robot
from sim_core.plant import Plant
from sim_core.simulator import Simulator

from closed_loop_sim import closed_loop_columns, open_loop_columns


@pytest.mark.parametrize("robot,joint,kp", [("hydrolek", "j2", 10.0), ("hydrolek", "j2", 60.0), ("harvester", "boom", 20.0)])
def test_a_p_controlled_record_is_closed_loop(robot, joint, kp):
    spec = load_robot(robot)
    cols = closed_loop_columns(spec, joint, kp=kp, duration=20.0, seed=2)
    ev = joint_evidence(cols[f"u_{joint}"], cols[f"q_{joint}"], spec.joint(joint).command_range)
    assert ev["closed_loop"] and ev["correlation"] <= CORRELATION_LIMIT
    assert ev["gain"] == pytest.approx(kp, rel=0.05)
    assert ev["lag_samples"] == 0


@pytest.mark.parametrize("robot,joint", [("hydrolek", "j2"), ("harvester", "boom")])
def test_an_open_loop_prbs_record_is_not(robot, joint):
    spec = load_robot(robot)
    rng = np.random.default_rng(5)
    for seed in (1, 2):
        cols = open_loop_columns(spec, joint, duration=20.0, seed=seed)
        u, y = cols[f"u_{joint}"], cols[f"q_{joint}"]
        assert not joint_evidence(u, y, spec.joint(joint).command_range)["closed_loop"]
        # a noisy analog command does not follow the sensor either
        noisy = u + rng.normal(0.0, 0.05, u.size)
        ev = joint_evidence(noisy, y, spec.joint(joint).command_range)
        assert not ev["closed_loop"] and abs(ev["correlation"]) < 0.2


@pytest.mark.parametrize("robot,joint,kp", [("hydrolek", "j2", 15.0), ("hydrolek", "j2", 60.0), ("harvester", "boom", 20.0)])
@pytest.mark.parametrize("hz", [0.1, 0.3])
def test_a_loop_tracking_a_moving_set_point_is_closed_loop(robot, joint, kp, hz):
    """A sine to track: the command's increments follow the set point's, which the joint follows too,
    so the increments alone do not show the loop; what is left after a local quadratic in time does,
    and gives the controller's gain."""
    spec = load_robot(robot)
    q0 = float(spec.joint(joint).settings["initial_position"])
    t = np.arange(30 * 50 + 1) / 50.0
    cols = closed_loop_columns(spec, joint, kp=kp, duration=30.0, seed=2, reference=q0 + 0.25 * np.sin(2 * np.pi * hz * t))
    u, y = cols[f"u_{joint}"], cols[f"q_{joint}"]
    assert not increments_evidence(u, y, spec.joint(joint).command_range)["closed_loop"]
    ev = joint_evidence(u, y, spec.joint(joint).command_range, cols["time"])
    assert ev["closed_loop"] and ev["test"] == "local_residuals" and ev["correlation"] <= CORRELATION_LIMIT
    assert ev["lag_samples"] == 0 and ev["gain"] == pytest.approx(kp, rel=0.05)


@pytest.mark.parametrize("robot,joint,kp,ti,increments_find_it", [
    ("hydrolek", "j2", 15.0, 5.0, True), ("harvester", "boom", 60.0, 2.0, True),
    ("hydrolek", "j2", 15.0, 0.3, False), ("harvester", "boom", 20.0, 0.5, False)])
def test_a_pi_loop_on_steps_gives_its_proportional_gain(robot, joint, kp, ti, increments_find_it):
    """A PI controller: its integral adds ``kp e dt / ti`` to the command's increments, in step with the
    joint's motion to close the error ``e``, so the increments give the proportional gain low by about
    the loop's time constant over ``ti`` (or miss the loop); after the local quadratic the integral's
    smooth action is gone, and that correlation is the stronger, so it is the evidence."""
    spec = load_robot(robot)
    cols = closed_loop_columns(spec, joint, kp=kp, duration=30.0, seed=2, ti=ti)
    u, y, rng = cols[f"u_{joint}"], cols[f"q_{joint}"], spec.joint(joint).command_range
    first = increments_evidence(u, y, rng)
    ev = joint_evidence(u, y, rng, cols["time"])
    assert ev["closed_loop"] and ev["test"] == "local_residuals" and ev["correlation"] < first["correlation"]
    assert ev["lag_samples"] == 0 and ev["gain"] == pytest.approx(kp, rel=0.05)
    assert first["closed_loop"] == increments_find_it and first["gain"] < 0.85 * kp   # the increments' own answer


@pytest.mark.parametrize("robot,joint,kp,increments_find_it", [("hydrolek", "j2", 15.0, False),
                                                            ("harvester", "boom", 60.0, True)])
def test_a_controller_that_parks_its_valve_is_closed_loop(robot, joint, kp, increments_find_it):
    """A PI controller that parks the valve at 0 V once its joint settles within 0.01 rad (or m): half
    the record or more the command holds and does not act on the reading, whose noise would dilute
    the correlation; over the windows where the command changes at every step, it is the loop's."""
    spec = load_robot(robot)
    cols = closed_loop_columns(spec, joint, kp=kp, duration=30.0, seed=2, ti=1.0, settle_band=0.01)
    u, y, rng = cols[f"u_{joint}"], cols[f"q_{joint}"], spec.joint(joint).command_range
    assert np.mean(u == 0.0) > 0.4
    ev = joint_evidence(u, y, rng, cols["time"])
    assert ev["closed_loop"] and ev["test"] == "local_residuals" and ev["lag_samples"] == 0
    assert ev["gain"] == pytest.approx(kp, rel=0.05)
    assert increments_evidence(u, y, rng)["closed_loop"] == increments_find_it


def test_the_reference_pid_of_mars_nd_is_closed_loop_on_every_joint_it_moves():
    """The paper's joint PID (controllers/pid.py: a filtered derivative, deadband compensation, the
    valve parked within a settle band) driving MARS-ND through its targets, 30 s at 200 Hz."""
    from controllers.experiment import run_local
    from controllers.scenarios import SCENARIOS
    scenario = SCENARIOS["mars_nd"]
    trace = run_local(scenario, "simulated", 30.0, None)
    spec = load_robot(scenario.robot)
    t, U, Q = np.asarray(trace["t"]), np.asarray(trace["u"]), np.asarray(trace["angle"])
    moved = [a for a in range(U.shape[1]) if np.ptp(U[:, a]) > 0]
    assert len(moved) >= 6
    for a in moved:
        j = spec.joint_names[a]
        assert np.mean(U[:, a] == 0.0) > 0.3, j                  # parked much of the time
        ev = joint_evidence(U[:, a], Q[:, a], spec.joint(j).command_range, t)
        assert ev["closed_loop"] and ev["lag_samples"] == 0, (j, ev)


def test_a_moving_set_point_on_an_uneven_clock_is_found_in_time_not_in_samples():
    """Samples 10 % uneven, a P loop reading a noisy sensor around an ideal valve, tracking a 0.3 Hz
    sine: the set point moves by more or less per sample, which a local fit over sample numbers reads
    as command changes the reading did not cause; fitted over the samples' times it does not."""
    rng = np.random.default_rng(4)
    n, kp = 3000, 100.0
    t = np.cumsum(0.02 * (1.0 + rng.uniform(-0.1, 0.1, n)))
    r = 0.3 * np.sin(2 * np.pi * 0.3 * t)
    q, y, u = np.zeros(n), np.zeros(n), np.zeros(n)
    for k in range(n):
        y[k] = q[k] + rng.normal(0, 1e-5)                     # what the controller reads and the log keeps
        u[k] = np.clip(kp * (r[k] - y[k]), -10, 10)
        if k < n - 1:
            q[k + 1] = q[k] + 0.03 * (t[k + 1] - t[k]) * u[k]
    in_samples = joint_evidence(u, y, (-10.0, 10.0))          # no clock: evenly spaced
    ev = joint_evidence(u, y, (-10.0, 10.0), t)
    assert ev["closed_loop"] and ev["test"] == "local_residuals" and ev["lag_samples"] == 0
    assert ev["gain"] == pytest.approx(kp, rel=0.05)
    assert not in_samples["closed_loop"]


@pytest.mark.parametrize("robot,joint", [("hydrolek", "j2"), ("harvester", "boom")])
def test_an_open_loop_multisine_is_not(robot, joint):
    """A smooth exogenous command: neither its increments nor its local residuals follow the reading."""
    spec = load_robot(robot)
    rng = np.random.default_rng(3)
    t = np.arange(1500) / 50.0
    us = sum(np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in (0.15, 0.35, 0.7, 1.3, 2.1))
    U = np.zeros((t.size, len(spec.joints)))
    a = spec.joint_names.index(joint)
    U[:, a] = 4.5 * us / np.abs(us).max()
    y = Simulator(Plant(spec).create_context(seed=3)).run(t, U).act[:, a, L.YA_ANGLE]
    ev = joint_evidence(U[:, a], y, spec.joint(joint).command_range, t)
    assert not ev["closed_loop"]


def test_feedback_one_sample_late_and_saturated():
    """A controller acting on the previous sample's reading, its command clipped at +-10 V: found at lag 1."""
    rng = np.random.default_rng(0)
    n = 3000
    r = np.repeat(rng.uniform(-0.3, 0.3, n // 150 + 1), 150)[:n]
    y = np.zeros(n)
    u = np.zeros(n)
    for k in range(1, n):
        u[k] = np.clip(40.0 * (r[k] - y[k - 1]), -10, 10)
        y[k] = y[k - 1] + 0.002 * u[k] + rng.normal(0, 5e-4)
    ev = joint_evidence(u, y, (-10.0, 10.0))
    assert ev["closed_loop"] and ev["lag_samples"] == 1 and ev["gain"] == pytest.approx(40.0, rel=0.05)


def _integrator_loop(kp: float, speed_per_volt: float, dt: float = 0.02, n: int = 3000, seed: int = 0):
    """A joint whose speed is ``speed_per_volt`` x command under ``u = kp (r - y)``, set points held 3 s."""
    rng = np.random.default_rng(seed)
    r = np.repeat(rng.uniform(-0.3, 0.3, n // 150 + 1), 150)[:n]
    y, u = np.zeros(n), np.zeros(n)
    for k in range(1, n):
        u[k] = np.clip(kp * (r[k] - y[k - 1]), -10, 10)
        y[k] = y[k - 1] + speed_per_volt * dt * u[k] + rng.normal(0, 5e-4)
    return u, y


@pytest.mark.parametrize("kp,speed_per_volt", [(40.0, 0.1), (10.0, 0.1), (40.0, 0.02)])
def test_the_loop_time_constant_is_one_over_gain_times_speed_per_volt(kp, speed_per_volt):
    u, y = _integrator_loop(kp, speed_per_volt)
    ev = joint_evidence(u, y, (-10.0, 10.0))
    tau = time_constant(u, y, 0.02, ev["gain"], (-10.0, 10.0))
    assert tau == pytest.approx(1.0 / (kp * speed_per_volt), rel=0.1)


def test_restarted_angle_fits_score_the_motion_not_an_integrated_bias():
    """On a closed-loop record, a model whose flow is biased drifts without end when replayed open loop;
    restarted from the record every window, its angle error stays within bias x window, so a model with
    the right motion and a small bias outscores one with a lag on the restarted channel, while over the
    whole record (the angle channel) the bias's drift outweighs the lag. Both channels enter the score."""
    dt, n = 0.02, 3000
    u, y = _integrator_loop(40.0, 0.1, dt=dt, n=n, seed=3)
    t = np.arange(n) * dt
    rec = Record("loop", t, u[:, None], {"j": y}, {}, ["j"], ["j"], {"j": 0.0})
    prob = oe.Problem(rec, ["j"], start=1800).restarting(50)
    truth = np.cumsum(0.1 * dt * u)
    drifting = truth + 0.004 * t                                   # 4 mrad/s of flow bias
    lagging = np.cumsum(0.1 * dt * np.r_[np.zeros(5), u[:-5]])     # 100 ms late

    def fits(sim):
        return prob.fits_of({("j", "angle"): sim[1800:], ("j", "velocity"): y[1800:]})["j"]

    assert fits(drifting)["angle"] < fits(lagging)["angle"]
    assert fits(drifting)["restarted"] > fits(lagging)["restarted"]
    f = fits(lagging)
    assert f["score"] == pytest.approx((f["angle"] + f["restarted"] + f["velocity"]) / 3)
    # restarted, the biased model's error is what the bias adds within one window (1 s) plus noise
    resid = y[1800:] - prob.restarted("j", drifting[1800:])
    assert np.max(np.abs(resid)) < 0.004 * 1.0 + 0.01
    # the noise-free motion keeps a fit near the noise ceiling when restarted (the record's noise is a
    # random walk, which the whole-record angle carries too)
    assert fits(truth)["restarted"] > 90.0
    # an open-loop problem has no restarted channel
    assert "restarted" not in oe.Problem(rec, ["j"], start=1800).fits_of(
        {("j", "angle"): truth[1800:], ("j", "velocity"): y[1800:]})["j"]


def test_diagnose_reports_a_closed_loop_record(cli, tmp_path):
    spec = load_robot("hydrolek")
    cols = closed_loop_columns(spec, "j2", kp=15.0, duration=30.0, seed=3)
    write_csv(tmp_path / "cl.csv", cols)
    proc = cli("diagnose", "--robot", "hydrolek", tmp_path / "cl.csv", "--report", tmp_path / "rep",
               "--effects", "delay", "--quiet")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    assert d["closed_loop"] is True
    ev = d["closed_loop_evidence"]["joints"]["j2"]
    assert ev["closed_loop"] and ev["gain"] == pytest.approx(15.0, rel=0.05)
    assert "delay shows as phase" in d["closed_loop_evidence"]["note"]
    assert any("closed loop" in n for n in d["data"]["notes"])
    # its validation angle restarts from the record every RESTART_TAUS loop time constants
    assert ev["time_constant_s"] > 0
    assert d["validation"]["angle_restart_s"] == pytest.approx(RESTART_TAUS * ev["time_constant_s"], rel=0.02)
    html = (tmp_path / "rep" / "report.html").read_text()
    assert "Closed-loop record" in html and "limit" in html
