"""The ceiling a period-mean replay allows (step_timing.py): which periods step, the drawn commands,
how the replay's misfit joins the noise's, and a record whose every cause is named once it does."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rig_records import as_record, closed_loop_record
from sim_core.identification import step_timing as stt
from sim_core.identification.diagnosis import run
from sim_core.model.spec import load_robot


def _p_loop(reference, gain=20.0, n=400, limit=None, seed=1):
    """A P law's log: a joint that closes 20 % of its error per sample on ``reference`` (one value per
    sample), with 1 mrad of noise read by the controller; the command rounded like a log's."""
    rng = np.random.default_rng(seed)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = y[k - 1] + 0.2 * (reference[k - 1] - y[k - 1])
    y_read = y + rng.normal(0.0, 1e-3, n)
    u = np.round(gain * (reference - y_read), 3)
    if limit is not None:
        u = np.clip(u, -limit, limit)
    return u, y_read


def test_the_periods_in_which_the_set_point_steps_are_found_and_no_others():
    r = np.zeros(400)
    r[100:], r[250:] = 0.3, -0.2                 # steps between samples 99-100 and 249-250
    u, y = _p_loop(r)
    assert stt.step_periods(u, y, 20.0).tolist() == [99, 249]
    t = np.arange(400) / 50.0
    u, y = _p_loop(0.3 * np.sin(2 * np.pi * 0.2 * t))          # a smooth set point has no step
    assert stt.step_periods(u, y, 20.0).size == 0
    assert stt.step_periods(u, y, 0.0).size == 0                # no loop gain: nothing to say


def test_a_period_saturated_at_both_ends_carries_no_uncertainty():
    r = np.zeros(400)
    r[100:] = 3.0                                # a step that saturates the command for a while
    u, y = _p_loop(r, limit=10.0)
    ks = stt.step_periods(u, y, 20.0, (-10.0, 10.0))
    assert 99 in ks.tolist()
    assert all(not (abs(u[k]) == 10.0 and abs(u[k + 1]) == 10.0) for k in ks)


def test_each_step_periods_mean_is_drawn_between_its_two_samples_and_the_rest_is_the_period_mean():
    U = np.column_stack([[0.0, 0.0, 8.0, 6.0, 5.0], [1.0, 2.0, 3.0, 4.0, 5.0]])
    rng = np.random.default_rng(0)
    draws = np.array([stt.drawn_commands(U, {0: np.array([1])}, rng) for _ in range(200)])
    assert np.all((draws[:, 1, 0] >= 0.0) & (draws[:, 1, 0] <= 8.0))
    assert draws[:, 1, 0].std() == pytest.approx(8.0 / math.sqrt(12.0), rel=0.15)   # uniform over the period
    assert np.all(draws[:, [0, 2, 3], 0] == [0.0, 7.0, 5.5])
    assert np.all(draws[:, :, 1] == U[:, 1])                     # a column without steps stays as logged


def test_the_replays_misfit_adds_to_the_noise_in_squares():
    y = np.sin(np.linspace(0.0, 6.0, 300))
    den = float(np.linalg.norm(y - y.mean()))
    assert stt.ceiling(95.0, y, 0.0) == pytest.approx(95.0)
    extra = (0.05 * den) ** 2                    # as large as the noise's misfit
    assert stt.ceiling(95.0, y, extra) == pytest.approx(100.0 * (1.0 - 0.05 * math.sqrt(2.0)))


def test_a_clean_rig_on_a_log_slower_than_its_controller_is_judged_against_the_ceiling_the_log_allows(tmp_path):
    """The clean rotary rig under a 1 kHz P loop logged at 50 Hz (seed 2): the baseline fits everything
    but the whole-record angle's drift, which the steps' instants within their 20 ms alone leave.
    Judged against the noise alone its score sits more than 2 points under the ceiling (unexplained);
    against the ceiling the log allows, it is clean."""
    import subprocess
    import sys

    rig = tmp_path / "rig"
    subprocess.run([sys.executable, "-m", "sim_core.cli", "rig", "new", "rotary", "--out", str(rig)], check=True,
                   capture_output=True)
    spec = load_robot(rig)
    j = spec.joint_names[0]
    i = spec.tree.index(spec.joint(j).dof)
    span = float(spec.tree.upper[i] - spec.tree.lower[i])
    rows, _ = closed_loop_record(rig, hidden=None, seed=2, start_offset=0.05 * span,
                                 off={f"joints.{j}.valve.rated_flow": 1.2, "supply.pressure": 0.85}, log_every=20)
    d = run(spec, as_record(spec, rows), progress=False).to_json()
    hold = d["closed_loop_evidence"]["command_hold"]
    assert hold["replay"] == "period_mean"
    assert hold["step_timing"]["step_periods"][j] >= 10                # a step every 1.5-4 s of 60 s
    lost = hold["step_timing"]["ceiling_points_lost"][j]
    assert lost["angle"] > 1.0 and lost["angle"] > lost["restarted"]   # the whole-record angle integrates it
    assert d["verdict"] == "no_significant_discrepancy", (d["selected"], d["unexplained"])
    ceilings = d["decision"]["channel_ceilings"][j]
    noise_only = np.mean([c + lost[ch] for ch, c in ceilings.items()])
    assert noise_only - d["baseline"]["score"][j] > 2.0                # the noise alone: more than the 2 points
