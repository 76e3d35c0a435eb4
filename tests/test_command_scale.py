"""A command logged in another scale than the valve saw (identification/command_scale.py): the rules
on synthetic figures, then the user's way: the boom rig's closed-loop log with its command logged as a
fraction of the amplifier's +-10 V -> ``diagnose`` -> the cause named with the replay that fixes it ->
the advice followed gives a clean diagnosis.

Expected values come from the figures and the log written here (the scale put in), not from the check."""

import numpy as np
import pytest

from conftest import run_cli
from rig_records import diagnose_log, rig_log
from sim_core.identification.command_scale import FULL_SCALE_SHARE, SCALE_LIMIT, causes, factor, ratio, too_fast
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
