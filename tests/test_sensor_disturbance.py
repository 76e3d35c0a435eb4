"""Interference on a rig's position sensor (sim_core/identification/sensor_disturbance.py): mains hum
on the potentiometer's wiring, sampled by the 50 Hz logger whose clock wanders (tests/rig_records.py
jitters each period by up to 10 %), is a disturbance no motion of the joint makes. ``diagnose`` must
not name an effect of the bank for it, and says the sensor first among the record's causes. The
clean log of the same rig and seed reads no discrepancy in tests/test_rig_diagnosis.py's way; the
8 Hz mode of tests/test_diagnose_unexplained.py (a misfit of the motion, not white) keeps no such
cause."""

import json

import numpy as np
import pytest

from rig_records import closed_loop_record, write_headerless
from sim_core.identification.decision import misfit_in_noise


def test_hum_on_the_position_sensor_is_unexplained_with_the_sensor_as_its_cause(cli, tmp_path):
    assert cli("rig", "new", "cylinder", "--out", tmp_path / "rig").returncode == 0
    rows, _ = closed_loop_record(tmp_path / "rig", hidden=None, seed=6, start_offset=0.02,
                                 off={"joints.lift.valve.rated_flow": 0.9, "supply.pressure": 1.1})
    hz, volts = 49.95, 0.05                      # a mains hum 0.05 Hz off the log's rate, 50 mV at the sensor
    rows[:, 1] += volts * np.sin(2.0 * np.pi * hz * rows[:, 0] + 1.0)
    write_headerless(rows, tmp_path / "log.csv")
    proc = cli("diagnose", "--robot", tmp_path / "rig", tmp_path / "log.csv", "--no-header", "--column", "time=0",
               "--column", "q_lift=1:sensor_volts", "--column", "u_lift=2", "--report", tmp_path / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    assert d["verdict"] == "unexplained_discrepancy" and d["selected"] == [], (d["selected"], d["unexplained"])
    u = d["unexplained"]
    found = u["sensor_disturbance"]["lift"]
    rho = d["residual_tests"]["extended"]["lift"]["autocorrelation"]
    assert len(rho) == 20 and max(map(abs, rho)) <= 0.3 and found["largest_autocorrelation"] == pytest.approx(
        max(map(abs, rho)), abs=1e-3)
    far = {c["channel"]: (c["ceiling"] - c["fit"], misfit_in_noise(c["fit"], c["ceiling"])) for c in found["channels"]}
    assert far["velocity"][0] > u["far_points"] and far["velocity"][1] > u["far_noise"]
    assert u["record_causes"][0].startswith("the position of lift carries a disturbance")
    assert "mains_tone" not in u      # 50 Hz at a 50 Hz log folds to near 0 Hz: a random walk, no line
    assert "parameter_drift" not in u  # nor is the rig said to change
    assert any("controller's rate" in c for c in u["record_causes"][1:])     # closed loop: still listed after it
