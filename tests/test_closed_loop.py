"""Closed-loop records are recognised (the command follows the position reading), open-loop ones are
not, and diagnose says so in diagnosis.json and the report."""

import json

import numpy as np
import pytest

from sim_core.dataset import write_csv
from sim_core.identification.closed_loop import CORRELATION_LIMIT, joint_evidence
from sim_core.model.spec import load_robot

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
    html = (tmp_path / "rep" / "report.html").read_text()
    assert "Closed-loop record" in html and "limit" in html
