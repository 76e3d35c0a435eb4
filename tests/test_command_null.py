"""A command whose zero is not the valve's null (identification/command_null.py): the rules on
synthetic signals, then the user's way: the clean cylinder rig's closed-loop log with its command
logged from a 0..10 V output nulled at 5 V -> ``diagnose`` -> the cause named with the replay that
fixes it -> the advice followed gives a clean diagnosis.

Expected values come from the signals and logs written here (the null put in), not from the check."""

import numpy as np
import pytest

from conftest import run_cli
from rig_records import diagnose_log, rig_log
from sim_core.effects.valve_offset import SPAN
from sim_core.identification.command_null import MIN_STILL, bound, causes, off_null, read_as, rest_command

DT = 0.02
RANGE = (-10.0, 10.0)


def held_steps(null=0.0, hold_noise=0.05, seed=0, n=3000):
    """A P loop's record in miniature: moves at a speed proportional to the command's distance from the
    valve's null, then holds at the null (plus a small holding command); position in m."""
    rng = np.random.default_rng(seed)
    u = np.empty(n)
    k = 0
    while k < n:
        move, hold = rng.integers(20, 60), rng.integers(40, 120)
        u[k:k + move] = null + rng.choice([-1, 1]) * rng.uniform(2.0, 8.0)
        u[k + move:k + move + hold] = null + rng.normal(0.0, hold_noise, max(0, min(hold, n - k - move)))
        k += move + hold
    q = 0.25 + np.cumsum(0.002 * (u - null)) * DT
    return u, q


def test_the_rest_command_is_where_the_joint_stands_still():
    for null in (0.0, 0.4, 5.0, -3.0):
        u, q = held_steps(null)
        rest = rest_command(u, q, DT, (-20.0, 20.0))
        assert rest["median"] == pytest.approx(null, abs=0.05)
        assert rest["p10"] < null < rest["p90"]
        assert 0.3 < rest["still_share"] < 0.9         # the holds: 40-120 samples of every 60-180


def test_a_null_beyond_the_valve_offset_bound_is_flagged_and_within_it_is_not():
    b = bound(RANGE)
    assert b == pytest.approx(SPAN * 10.0)
    for null, flagged in ((0.0, False), (0.9 * b, False), (-0.9 * b, False), (1.2 * b, True), (-1.2 * b, True),
                          (5.0, True)):
        u, q = held_steps(null)
        assert off_null(rest_command(u, q, DT, (-20.0, 20.0)), RANGE) is flagged, null


def test_a_wide_deadband_straddling_the_null_is_not_flagged():
    # a controller stopping anywhere inside a 2 V deadband: rest commands spread over both signs,
    # their median may sit past the bound
    b = bound(RANGE)
    straddle = {"median": 1.6, "p10": -1.9, "p90": 1.95, "still_share": 0.4}
    assert straddle["median"] > b and not off_null(straddle, RANGE)
    assert off_null({**straddle, "p10": b + 0.1}, RANGE)            # all of it past the bound
    assert off_null({"median": -1.8, "p10": -1.95, "p90": -b - 0.1, "still_share": 0.4}, RANGE)


def test_a_joint_that_barely_stands_still_is_not_judged():
    rest = {"median": 5.0, "p10": 4.9, "p90": 5.1, "still_share": 0.5 * MIN_STILL}
    assert not off_null(rest, RANGE)
    assert off_null({**rest, "still_share": 2 * MIN_STILL}, RANGE)
    assert not off_null(None, RANGE)


def test_samples_at_an_end_stop_or_a_saturated_command_do_not_count():
    u, q = held_steps(0.0)
    q = q - q.min()                               # the joint's lower limit at the record's lowest reading
    u_sat = u.copy()
    u_sat[q < 0.01] = 9.0                          # pushing into the stop: still, at a large command
    rest = rest_command(u_sat, q, DT, RANGE, limits=(0.0, 10.0))
    assert abs(rest["median"]) < 0.05
    ends = rest_command(u_sat, q, DT, RANGE)      # without the limits those samples count
    assert ends["p90"] > rest["p90"]
    u_lim = u.copy()
    u_lim[np.abs(u) < 1.0] = RANGE[1]             # standing still only with the command at its limit
    assert rest_command(u_lim, q, DT, RANGE) is None


def test_the_reading_advice_shifts_and_maps_a_unipolar_output():
    u = np.linspace(0.0, 10.0, 50)
    assert read_as(5.0, u, RANGE) == ["*1-5", "*2-10"]
    assert read_as(5.0, u, (-5.0, 5.0)) == ["*1-5", "*1-5"]
    assert read_as(2.0, u - 3.0, RANGE) == ["*1-2"]          # goes below 0 V: not a unipolar output
    assert read_as(2.0, u, RANGE) == ["*1-2"]                # null not mid-range


def test_the_cause_names_the_joint_the_null_and_the_fix():
    e = {"median": 5.007, "p10": 4.94, "p90": 5.06, "still_share": 0.24, "bound_v": 1.5,
         "read_as": ["*1-5.007", "*2-10"], "fit": -280.2, "fit_command_shifted": 44.9}
    (said,) = causes({"joints": {"lift": e}})
    assert "+5.01 V" in said and "24 %" in said and "+-1.5 V" in said
    assert "-280.2 % as recorded, 44.9 % with the command shifted by -5.01 V" in said
    assert "`--column u_lift=SOURCE:*1-5.007`" in said and "`--column u_lift=SOURCE:*2-10`" in said


# ---- the user's way --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def unipolar_log(tmp_path_factory):
    """The clean cylinder rig (valve +20 %, supply -15 %, start off) under its P controller, its command
    logged as a 0..10 V output nulled at 5 V: v = 5 + u / 2."""
    return rig_log(run_cli, tmp_path_factory.mktemp("unipolar"), "cylinder", lambda u: 5.0 + u / 2.0, start_offset=0.025,
                   off={"joints.lift.valve.rated_flow": 1.2, "supply.pressure": 0.85})


def test_a_unipolar_command_is_named_and_reading_it_mapped_fixes_it(cli, unipolar_log):
    d, printed = diagnose_log(cli, unipolar_log, "as_logged", "lift")
    assert d["verdict"] == "unexplained_discrepancy"
    e = d["unexplained"]["command_null"]["joints"]["lift"]
    assert e["median"] == pytest.approx(5.0, abs=0.3)          # the holding command: the null plus tenths
    assert e["read_as"][1] == "*2-10"
    assert e["fit_command_shifted"] > e["fit"] + 20
    cause = d["unexplained"]["record_causes"][0]
    assert "the command's zero is not the valve's null" in cause and "u_lift=SOURCE:*2-10" in cause
    assert "command's zero is not the valve's null" in printed
    fixed, _ = diagnose_log(cli, unipolar_log, "mapped", "lift", ":*2-10")
    assert fixed["verdict"] == "no_significant_discrepancy", fixed.get("unexplained")
