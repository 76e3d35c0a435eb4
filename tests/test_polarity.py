"""The sign check's rules on synthetic signals and fits (no simulation): which way a joint moves per
volt of command, when the record and the model disagree, and which reversal explains a record."""

import math

import numpy as np
import pytest

from sim_core.identification import polarity
from sim_core.model.spec import load_robot

DT = 0.02


def _motion(k, n=3000, seed=0):
    """A command of held random levels and the position it drives at ``k`` per second per volt."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-5.0, 5.0, n // 50), 50)
    return u, np.cumsum(k * u) * DT + 1e-5 * rng.standard_normal(u.size)


@pytest.mark.parametrize("k", [0.02, -0.03])
def test_direction_gives_the_speed_per_volt_and_its_sign(k):
    u, y = _motion(k)
    d = polarity.direction(u, y, DT)
    assert d["speed_per_volt"] == pytest.approx(k, rel=0.05)
    assert abs(d["correlation"]) > 0.9 and math.copysign(1.0, d["correlation"]) == math.copysign(1.0, k)


def test_direction_leaves_out_the_samples_at_the_command_limits():
    """At a command limit the joint may sit in its end stop and move either way; those samples do not count."""
    u, y = _motion(0.02)
    u[:1000] = 10.0                       # at the limit, the joint driven the other way (an end stop's rebound)
    y[:1000] = y[1000] + 0.01 * np.cos(np.linspace(0.0, 40.0, 1000))
    inside = polarity.direction(u, y, DT, command_range=(-10.0, 10.0))
    assert inside["speed_per_volt"] == pytest.approx(0.02, rel=0.05)
    assert polarity.direction(u, y, DT)["correlation"] < inside["correlation"]


def test_a_constant_command_or_position_gives_no_direction():
    u, y = _motion(0.02)
    assert polarity.direction(np.zeros_like(u), y, DT) == {"speed_per_volt": 0.0, "correlation": 0.0}
    assert polarity.direction(u, np.zeros_like(y), DT) == {"speed_per_volt": 0.0, "correlation": 0.0}


@pytest.mark.parametrize("record, model, reversed_", [
    (-0.97, 0.96, True),       # the record against the command, the model with it
    (0.97, -0.96, True),       # and the other way round
    (0.97, 0.96, False),       # the same sign: nothing reversed
    (-0.97, -0.96, False),
    (-0.3, 0.96, False),       # the record's relation too weak to tell (a joint barely moving, or held)
    (-0.97, 0.3, False),       # the model's too weak (it sits in an end stop)
])
def test_a_reversal_needs_opposite_signs_both_clear(record, model, reversed_):
    r = {"speed_per_volt": record, "correlation": record}
    m = {"speed_per_volt": model, "correlation": model}
    assert polarity.reversed_sign(r, m) is reversed_


def _entry(fit, cmd, pos):
    return {"reversed": True, "record": {"speed_per_volt": -0.018, "correlation": -0.99},
            "model": {"speed_per_volt": 0.016, "correlation": 0.99},
            "fit": fit, "fit_command_reversed": cmd, "fit_position_mirrored": pos}


@pytest.mark.parametrize("fits, best", [
    ((-95.0, 88.0, 11.0), "command"),
    ((-95.0, -125.0, 88.0), "position"),
    ((-95.0, 60.0, 55.0), None),          # both reversals fit alike: the record does not say which
    ((-95.0, -20.0, -60.0), None),        # the better reversal still misses (a fit below zero)
    ((30.0, 45.0, -60.0), None),          # too little above the record as it is
    ((-95.0, None, 88.0), "position"),    # a diverged replay counts as no fit
])
def test_the_reversal_named_is_the_one_that_explains_the_record(fits, best):
    assert polarity.explains(_entry(*fits)) == best


def test_the_causes_say_what_to_change():
    spec = load_robot("hydrolek")
    a = spec.get("joints.j2.sensor.A")
    res = {"joints": {"j2": _entry(-95.0, 88.0, 11.0), "j3": {**_entry(-95.0, -125.0, 88.0)},
                      "j1": {**_entry(-95.0, 88.0, 11.0), "reversed": False}}}
    lines = polarity.causes(res, spec)
    assert len(lines) == 2                                   # j1 is not reversed
    assert "on j2" in lines[0] and "command reversed explains it" in lines[0] and "u_j2=SOURCE:*-1" in lines[0]
    assert "on j3" in lines[1] and "position mirrored explains it" in lines[1]
    assert f"joints.j3.sensor.A = {-spec.get('joints.j3.sensor.A'):.6g}" in lines[1]
    assert "rad/s per V" in lines[0] and a != 0.0
