"""A command logged in another scale than the valve saw (identification/command_scale.py): the rules
on synthetic figures, then the user's way: the boom rig's closed-loop log with its command logged as a
fraction of the amplifier's +-10 V -> ``diagnose`` -> the cause named with the replay that fixes it ->
the advice followed gives a clean diagnosis. The same on the cylinder rig, where the calibration takes
up part of the scale: its flow gain at the end of its declared range (the record unexplained), or
freed beyond it in a named effect's place (the record explained, by a valve 20 times the spec's).

Expected values come from the figures and the log written here (the scale put in), not from the check."""

import numpy as np
import pytest

from conftest import run_cli
from rig_records import diagnose_log, rig_log
from sim_core.identification.beyond_range import found
from sim_core.identification.command_scale import (FULL_SCALE_SHARE, SCALE_LIMIT, FlowGain, causes, factor, off_scale,
                                                   ratio, reversed_causes, too_fast)
from sim_core.identification.polarity import CORRELATION_MIN
from sim_core.model.spec import load_robot

RANGE = (-10.0, 10.0)


def d(speed, corr=0.97):
    return {"speed_per_volt": speed, "correlation": corr}


def test_the_ratio_needs_both_moving_with_their_command_the_same_way():
    assert ratio(d(0.4), d(0.04)) == pytest.approx(10.0)
    assert ratio(d(-0.4, -0.97), d(-0.04, -0.95)) == pytest.approx(10.0)    # both reversed alike: a ratio
    assert ratio(d(-0.4, -0.97), d(0.04)) is None                            # opposite ways: polarity's
    assert ratio(d(0.4, 0.9 * CORRELATION_MIN), d(0.04)) is None             # the record does not follow it
    assert ratio(d(0.4), d(0.04, 0.9 * CORRELATION_MIN)) is None
    assert ratio(d(0.4), d(0.0, 0.97)) is None


def test_only_a_record_faster_than_the_limit_is_flagged():
    assert too_fast(1.1 * SCALE_LIMIT) and not too_fast(0.9 * SCALE_LIMIT)
    assert not too_fast(0.01)              # much slower: a stalled or loaded joint does that too
    assert not too_fast(None)


def test_the_factor_maps_the_largest_command_onto_the_range_end_where_the_ratio_is_near_or_beyond():
    u = np.linspace(-1.0, 1.0, 101)                      # a +-10 V loop logged as a fraction
    assert factor(10.3, u, RANGE) == pytest.approx(10.0)          # beyond the range: the full-scale factor
    assert factor(10.0 * (1 - 0.9 * FULL_SCALE_SHARE), u, RANGE) == pytest.approx(10.0)     # near it
    far = 10.0 * (1 - 1.5 * FULL_SCALE_SHARE)
    assert factor(far, u, RANGE) == pytest.approx(far)             # a loop that never reached the range's end
    assert factor(4.0, np.zeros(5), RANGE) == 4.0


def test_the_cause_names_the_joint_the_ratio_and_the_fix():
    e = {"record_speed_per_volt": 0.397, "model_speed_per_volt": 0.0384, "ratio": 10.34, "factor": 10.0,
         "fit": -58.4, "fit_command_scaled": 99.0}
    (said,) = causes({"joints": {"j2": e}}, load_robot("hydrolek"))
    assert "10.3 times faster" in said and "+0.397 rad/s per V" in said
    assert "-58.4 % as recorded, 99.0 % with the command scaled by 10 (its largest value" in said
    assert "`--column u_j2=SOURCE:*10`" in said
    (said,) = causes({"joints": {"j2": {**e, "model_flow_gain_share": 4.0, "flow_gain_share": 1.03}}},
                     load_robot("hydrolek"))
    assert "calibrated model +0.0384 with its flow gain at 4 times the spec's" in said
    assert "and the flow gain at 1.03 times the spec's (inside its declared range)" in said


def test_a_command_already_at_its_range_end_is_not_read_scaled():
    e = {"record_speed_per_volt": 17.8, "model_speed_per_volt": 0.305, "ratio": 58.3, "factor": 1.0,
         "fit": -9.8, "fit_command_scaled": -9.8}
    (said,) = causes({"joints": {"swing": e}}, load_robot("hydrolek"))
    assert "already reaches its range's end" in said and "--column u_swing" not in said
    assert "the time column's unit" in said
    (said,) = causes({"joints": {"swing": {**e, "factor": 1.1 * SCALE_LIMIT}}}, load_robot("hydrolek"))
    assert "already reaches" not in said and f"`--column u_swing=SOURCE:*{1.1 * SCALE_LIMIT:.4g}`" in said


def test_a_command_both_reversed_and_scaled_is_read_with_a_negative_factor():
    e = {"record_speed_per_volt": -0.148, "model_speed_per_volt": 0.0156, "ratio": 9.48, "factor": -10.0,
         "fit": -38.2, "fit_command_scaled": 94.8, "flow_gain_share": 0.948}
    (said,) = reversed_causes({"joints": {"j2": e}}, load_robot("hydrolek"))
    assert "moves against its command and 9.48 times faster" in said and "both reversed and in another scale" in said
    assert "94.8 % with the command scaled by -10 (its largest value" in said and "`--column u_j2=SOURCE:*-10`" in said


def test_a_flow_gain_is_off_scale_beyond_the_limit_either_way():
    assert off_scale(1.1 * SCALE_LIMIT) and not off_scale(0.9 * SCALE_LIMIT)
    assert off_scale(1.0 / (1.1 * SCALE_LIMIT)) and not off_scale(1.0 / (0.9 * SCALE_LIMIT))
    assert FlowGain("joints.j.valve.rated_flow", 2e-4, 8e-4, (5e-5, 8e-4)).share == pytest.approx(4.0)


def _stand_in(param, value, effect, score, with_effect, **more):
    return {"parameter": param, "value": value, "in_place_of": {"effect": effect, "joint": "lift", "params": {}},
            "score": score, "score_with_effect": with_effect, **more}


def test_a_calibration_beyond_its_declared_range_is_said_once_per_parameter_with_the_scale_to_check():
    key = "joints.lift.valve.rated_flow"
    beyond = dict(nominal=2e-4, declared_range=[5e-5, 8e-4], unit="m^3/s")
    scale = {"joint": "lift", "ratio": 17.9, "factor": 20.0, "flow_gain": 1.79e-4, "flow_gain_share": 0.895,
             "fit": 99.9, "fit_command_scaled": 99.8}
    rows = [_stand_in(key, 3.5e-3, "joint_compliance", 99.5, 9.1, **beyond, command_scale=scale),
            _stand_in(key, 3.6e-3, "area_ratio", 99.4, 40.0, **beyond),
            _stand_in("joints.lift.cylinder.viscous_friction", 50.0, "coulomb_friction", 99.0, 98.0)]   # held: no range
    (line,) = found({"stand_ins": rows})
    assert line.startswith(f"{key} = 0.0035 m^3/s (spec 0.0002), beyond its declared range [5e-05, 0.0008]")
    assert "in place of joint_compliance on lift, area_ratio on lift" in line and "+90.40 points" in line
    assert "passes 17.9 times the spec's flow per volt" in line and "`--column u_lift=SOURCE:*20`" in line
    (plain,) = found({"stand_ins": [rows[1]]})
    assert "times the spec's flow" not in plain           # within the scale limit: no scale to check
    assert found({"stand_ins": [rows[2]]}) == []


# ---- the user's way --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def fraction_log(tmp_path_factory):
    """The boom rig (valve +20 %, supply -15 %, start off) under its P controller, its +-10 V command
    logged as a fraction of the amplifier's range: v = u / 10."""
    return rig_log(run_cli, tmp_path_factory.mktemp("fraction"), "boom", lambda u: u / 10.0, start_offset=0.05,
                   off={"joints.boom.valve.rated_flow": 1.2, "supply.pressure": 0.85})


def test_a_command_logged_as_a_fraction_is_named_and_reading_it_scaled_fixes_it(cli, fraction_log):
    d, printed = diagnose_log(cli, fraction_log, "as_logged", "boom")
    assert d["verdict"] == "unexplained_discrepancy"
    e = d["unexplained"]["command_scale"]["joints"]["boom"]
    assert 10.0 / 3 < e["ratio"] < 10.0 * 3          # the 10 put in, the model's flow gain off by tens of %
    assert e["factor"] == pytest.approx(10.0, rel=1e-3)      # the loop saturated at +-10 V: logged +-1
    assert e["fit_command_scaled"] > e["fit"] + 20
    cause = next(c for c in d["unexplained"]["record_causes"] if "times faster per volt" in c)
    assert "u_boom=SOURCE:*10`" in cause and "times faster per volt" in printed
    fixed, _ = diagnose_log(cli, fraction_log, "scaled", "boom", f":*{e['factor']:g}")
    assert fixed["verdict"] == "no_significant_discrepancy", fixed.get("unexplained")
    assert "command_scale" not in (fixed.get("unexplained") or {})


# ---- the cylinder rig: the calibration takes up part of the scale -----------------------------------


def cylinder_log(tmp_path_factory, name, divisor, seed, ti):
    """The cylinder rig (valve -10 %, supply +10 %, start off) under its controller (``ti``: PI), its
    command logged divided by ``divisor``."""
    return rig_log(run_cli, tmp_path_factory.mktemp(name), "cylinder", lambda u: u / divisor, start_offset=0.02,
                   off={"joints.lift.valve.rated_flow": 0.9, "supply.pressure": 1.1}, seed=seed, ti=ti)


def _flow_gain(d):
    return next(c for c in d["calibration"]["changes"] if c["parameter"] == "joints.lift.valve.rated_flow")


def test_a_flow_gain_stopped_at_its_range_end_counts_towards_the_scale(cli, tmp_path_factory):
    """u/5 under PI: the calibration takes the flow gain to the end of its declared range (4 x the spec's)
    and the record stays unexplained, 1.2 times faster per volt than that model: 5 times the spec's valve."""
    root = cylinder_log(tmp_path_factory, "fifth", 5.0, seed=32, ti=2.0)
    d, printed = diagnose_log(cli, root, "as_logged", "lift")
    assert d["verdict"] == "unexplained_discrepancy"
    flow = _flow_gain(d)
    e = d["unexplained"]["command_scale"]["joints"]["lift"]
    assert e["model_flow_gain_share"] == pytest.approx(flow["value"] / flow["nominal"], rel=1e-3)
    assert e["model_flow_gain_share"] > 2.0                      # the calibration took up part of the 5
    assert 5.0 / 3 < e["ratio"] < 5.0 * 3 and e["factor"] == pytest.approx(5.0, rel=1e-3)
    assert 0.25 <= e["flow_gain_share"] <= 4.0                   # the rest, inside the declared range
    assert e["fit_command_scaled"] > e["fit"]
    assert "u_lift=SOURCE:*5`" in printed
    fixed, _ = diagnose_log(cli, root, "scaled", "lift", ":*5")
    assert fixed["verdict"] == "no_significant_discrepancy", fixed.get("unexplained")
    assert _flow_gain(fixed)["value"] / _flow_gain(fixed)["nominal"] == pytest.approx(0.9 * 1.1 ** 0.5, rel=0.3)


def test_a_flow_gain_freed_far_beyond_its_range_names_the_scale(cli, tmp_path_factory):
    """u/20 under P: the flow gain freed beyond its declared range in a named effect's place explains
    the record, at 20 times the spec's; the output says so and which scale to read the command in."""
    root = cylinder_log(tmp_path_factory, "twentieth", 20.0, seed=31, ti=None)
    d, printed = diagnose_log(cli, root, "as_logged", "lift")
    (row,) = {r["parameter"]: r for r in d["calibration"]["stand_ins"]}.values()
    assert row["parameter"] == "joints.lift.valve.rated_flow"
    lo, hi = row["declared_range"]
    assert not lo <= row["value"] <= hi
    e = row["command_scale"]
    assert 20.0 / 3 < e["ratio"] < 20.0 * 3 and e["factor"] == pytest.approx(20.0, rel=1e-3)
    assert lo <= e["flow_gain"] <= hi and e["fit_command_scaled"] > 90.0
    assert "calibrated beyond a declared range: joints.lift.valve.rated_flow" in printed
    html = (root / "as_logged" / "report.html").read_text()
    assert "Calibrated beyond a declared range</b>: joints.lift.valve.rated_flow" in html and "SOURCE:*20`" in html
    assert "u_lift=SOURCE:*20`" in printed
    fixed, fixed_printed = diagnose_log(cli, root, "scaled", "lift", ":*20")
    assert fixed["calibration"]["stand_ins"] == [] and "beyond a declared range" not in fixed_printed
    assert lo <= _flow_gain(fixed)["value"] <= hi


def test_a_command_logged_reversed_and_as_a_fraction_is_read_with_both(cli, tmp_path_factory):
    """-u/10 under P: the sign check finds the joint moving against its command and neither reversal
    alone explains it; reversed and scaled by 10 it does."""
    root = cylinder_log(tmp_path_factory, "reversed_tenth", -10.0, seed=31, ti=None)
    d, printed = diagnose_log(cli, root, "as_logged", "lift")
    assert d["verdict"] == "unexplained_discrepancy"
    assert d["unexplained"]["polarity"]["joints"]["lift"]["reversed"]
    e = d["unexplained"]["command_reversed_scale"]["joints"]["lift"]
    assert e["factor"] == pytest.approx(-10.0, rel=1e-3) and 10.0 / 3 < e["ratio"] < 10.0 * 3
    assert e["fit_command_scaled"] > e["fit"] + 20
    assert "u_lift=SOURCE:*-10`" in printed
    fixed, _ = diagnose_log(cli, root, "read_back", "lift", ":*-10")
    assert fixed["verdict"] == "no_significant_discrepancy", fixed.get("unexplained")

