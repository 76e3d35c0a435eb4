"""The scored matrix's "within reach" figure (``benchmarks/bench_diagnose_matrix.py``): which missed
singles no decision on the diagnosis's own fits could name without a false alarm. Synthetic rows, no
simulation."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_diagnose_matrix as matrix  # noqa: E402


def _clean(robot, k, best):
    return {"id": f"clean/{robot}/{k}", "group": "clean", "right": True, "best_gain": best}


def _single(robot, effect, k, right, truth_gain=None, calibration=None):
    r = {"id": f"single/{robot}/{effect}/{k}", "group": "singles", "right": right, "param_error_pct": None}
    if truth_gain is not None:
        r["truth_gain"] = truth_gain
    if calibration is not None:
        r["calibration"] = calibration
    return r


def _cal(truth, sigma, nominal=0.0):
    return {"parameter": "effects.sensor_offset.boom.offset", "nominal": nominal, "fitted": nominal,
            "sigma": sigma, "truth": truth, "identified": False, "found": False}


def test_the_clean_records_best_candidate_sets_each_robots_level():
    floors = matrix.clean_floors([_clean("rig_boom", 1, 0.05), _clean("rig_boom", 2, 0.15),
                                  _clean("hydrolek", 1, 0.4), _single("rig_boom", "delay", 1, True, 9.0)])
    assert floors == {"rig_boom": 0.15, "hydrolek": 0.4}


@pytest.mark.parametrize("gain, beyond", [(0.10, True), (0.15, True), (0.30, False)])
def test_a_miss_whose_own_fit_gains_no_more_than_a_clean_record_is_out_of_reach(gain, beyond):
    floors = {"rig_boom": 0.15}
    assert matrix.out_of_reach(_single("rig_boom", "coulomb_friction", 1, False, gain), floors) is beyond


def test_the_level_is_the_records_own_robots():
    # 0.3 points is below HydroLek's clean level but above the rig's: on the rig it could be named
    floors = {"rig_boom": 0.15, "hydrolek": 0.4}
    assert not matrix.out_of_reach(_single("rig_boom", "leakage", 1, False, 0.3), floors)
    assert matrix.out_of_reach(_single("hydrolek", "leakage", 1, False, 0.3), floors)


def test_a_right_single_is_within_reach_whatever_it_gained():
    assert not matrix.out_of_reach(_single("rig_boom", "leakage", 1, True, 0.0), {"rig_boom": 0.15})


def test_a_miss_whose_own_candidate_was_never_fitted_counts_as_within_reach():
    assert not matrix.out_of_reach(_single("rig_boom", "leakage", 1, False), {"rig_boom": 0.15})


@pytest.mark.parametrize("truth, sigma, beyond", [(0.02, 0.01, True), (0.03, 0.01, True), (0.02, 0.005, False),
                                                  (-0.02, 0.005, False)])
def test_a_calibrated_truth_within_three_sigma_of_the_spec_is_out_of_reach(truth, sigma, beyond):
    r = _single("rig_boom", "sensor_offset", 1, False, calibration=_cal(truth, sigma))
    assert matrix.out_of_reach(r, {"rig_boom": 0.15}) is beyond


def test_the_summary_gives_the_share_within_reach_of_the_singles_it_can_judge():
    rows = [_clean("rig_boom", 1, 0.15), _clean("hydrolek", 1, 0.1),
            _single("rig_boom", "deadband", 1, True, 40.0),
            _single("rig_boom", "coulomb_friction", 1, False, 0.05),                       # out
            _single("rig_boom", "leakage", 1, False, 1.8),                                 # in: a threshold's miss
            _single("rig_boom", "sensor_offset", 1, False, calibration=_cal(0.02, 0.03)),  # out
            _single("hydrolek", "payload", 1, False, 3.5),                                 # in
            _single("mars", "delay", 1, False, 0.0)]                                       # no clean level: not judged
    s = matrix.summary(rows)
    assert s["singles_judged_for_reach"] == 5
    assert s["singles_out_of_reach_ids"] == ["single/rig_boom/coulomb_friction/1", "single/rig_boom/sensor_offset/1"]
    assert s["singles_reach_pct"] == pytest.approx(60.0)
    assert s["clean_best_gain"] == {"hydrolek": 0.1, "rig_boom": 0.15}
