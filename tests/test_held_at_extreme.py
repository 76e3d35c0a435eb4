"""A joint held at the record's extreme while its command drives it further (an end stop the spec does
not have, a sensor at the end of its range): said in the record's notes and, when the misfit stays
unexplained, as a cause in the record. Unit checks on a P loop around an integrating joint (no
simulator), then a rig whose real travel is shorter than its spec's, end to end."""

import json
import math

import numpy as np
import pytest

from sim_core.identification import held_at_extreme as H

from rig_records import closed_loop_record, write_headerless

RATE = 50.0
RANGE = (-10.0, 10.0)


def p_loop(stop=0.38, levels=(0.1, 0.45, 0.2, 0.45, 0.15), hold=4.0, velocity_per_volt=0.02, kp=50.0,
           sign=1.0, noise=1e-4, seed=0):
    """A joint whose velocity is ``sign * velocity_per_volt * u`` (m/s per V), stopped at ``stop`` (m),
    under P control to piecewise-constant set points; returns (time, position read, command)."""
    rng = np.random.default_rng(seed)
    n = int(len(levels) * hold * RATE)
    t = np.arange(n) / RATE
    y, u = np.zeros(n), np.zeros(n)
    q = levels[0]
    for k in range(n):
        y[k] = q + noise * rng.standard_normal()
        r = levels[min(int(t[k] / hold), len(levels) - 1)]
        u[k] = np.clip(sign * kp * (r - y[k]), *RANGE)
        q = min(q + sign * velocity_per_volt * u[k] / RATE, stop)
    return t, y, u


def find(t, y, u, limits=(0.0, 0.5), noise=1e-4):
    return H.find(t, y, u, noise, RANGE, limits, 0.01)


def test_a_stop_inside_the_specs_range_is_found_with_its_value_and_share():
    t, y, u = p_loop()
    f = find(t, y, u)
    assert f is not None and f["side"] == "upper" and f["limit"] == 0.5
    assert f["value"] == pytest.approx(0.38, abs=5e-4)
    # two set points of 0.45 m, each held at the stop for most of its 4 s once the joint arrives
    assert f["runs"] == 2 and 4.0 <= f["seconds"] <= 8.0 and f["largest_command_v"] >= 2.0
    assert f["share"] == pytest.approx(f["seconds"] / t[-1], rel=0.05)
    text = H.note("lift", f, "m")
    assert "stays at 0.38" in text and "upper limit is 0.5 m" in text and text.startswith("lift: ")


def test_a_valve_wired_the_other_way_still_pushes_into_the_stop():
    """Direction from the record's own command-motion correlation: with the sign reversed the command
    that holds the joint against the upper stop is negative."""
    t, y, u = p_loop(sign=-1.0)
    f = find(t, y, u)
    assert f is not None and f["side"] == "upper" and np.median(u[np.abs(y - f["value"]) < 1e-3]) < -2.0


def test_the_lower_side_and_the_longest_held_side_is_reported():
    t, y, u = p_loop(stop=math.inf, levels=(0.3, -0.05, 0.2, -0.05, -0.05))
    y = np.maximum(y, 0.02)            # held at 0.02 m from below
    u = np.where(y <= 0.02, -10.0, u)  # ... with the command pushing it down
    f = find(t, y, u, limits=(-0.2, 0.5))
    assert f is not None and f["side"] == "lower" and f["value"] == pytest.approx(0.02, abs=1e-9)


def test_nothing_is_said_where_the_joint_is_free_or_stops_at_the_specs_own_limit():
    t, y, u = p_loop(stop=math.inf)                         # no stop: it reaches its set points
    assert find(t, y, u) is None
    t, y, u = p_loop(stop=0.5, levels=(0.1, 0.6, 0.2, 0.6, 0.15))
    assert find(t, y, u, limits=(0.0, 0.7)) is not None
    assert find(t, y, u, limits=(0.0, 0.505)) is None     # within the margin of the spec's limit: the model's stop


def test_a_joint_resting_at_its_extreme_with_a_small_command_is_not_held():
    """A joint at rest at its highest set point (quantised: repeating values) with the command near 0:
    not pushed, not held."""
    t, y, u = p_loop(stop=math.inf, levels=(0.1, 0.45, 0.45, 0.45, 0.2), noise=0.0)
    y = np.round(y / 1e-3) * 1e-3
    assert find(t, y, u, noise=0.0) is None


def test_short_flat_runs_are_reversals_not_blocks():
    t, y, u = p_loop()
    f = find(t, y, u)
    held = np.abs(y - f["value"]) <= 4e-4
    cut = y.copy()
    # break every held run into pieces shorter than the minimum run by a 0.1 s dip each 0.2 s
    idx = np.flatnonzero(held)
    cut[idx[(np.arange(idx.size) // int(0.1 * RATE)) % 3 == 2]] -= 0.01
    assert find(t, cut, u) is None


def test_a_rig_shorter_than_its_spec_is_said_to_be_held_and_diagnosed_right_with_its_real_range(cli, tmp_path):
    """A 0.5 m cylinder rig whose real travel ends at 0.38 m (a stop the spec does not have), under P
    control with set points up to 0.45 m: the record's notes and its unexplained misfit say where it
    is held; with the rig's real range in the spec the same record has nothing left to explain."""
    cli("rig", "new", "cylinder", "--out", tmp_path / "spec", check=True)
    cli("rig", "new", "cylinder", "--out", tmp_path / "real", check=True)
    urdf = tmp_path / "real" / "real.urdf"
    urdf.write_text(urdf.read_text().replace('upper="0.5"', 'upper="0.38"'))
    toml = tmp_path / "real" / "robot.toml"
    text = toml.read_text()
    assert "# stroke = 0.5 " in text
    toml.write_text(text.replace("# stroke = 0.5 ", "stroke = 0.5 "))    # the same cylinder, a shorter travel
    rows, _ = closed_loop_record(tmp_path / "real", hidden=None, off={"joints.lift.valve.rated_flow": 1.2}, seed=2,
                                 start_offset=0.025, reference_range=(0.1, 0.45))
    write_headerless(rows, tmp_path / "log.csv")
    reading = ["--no-header", "--column", "time=0", "--column", "q_lift=1:sensor_volts", "--column", "u_lift=2"]
    d = {}
    for robot in ("spec", "real"):
        proc = cli("diagnose", "--robot", tmp_path / robot, tmp_path / "log.csv", "--report", tmp_path / f"rep_{robot}",
                   "--quiet", *reading)
        assert proc.returncode == 0, proc.stderr
        d[robot] = json.loads((tmp_path / f"rep_{robot}" / "diagnosis.json").read_text())
    held = d["spec"]["data"]["held_at_extreme"]["lift"]
    assert held["side"] == "upper" and held["value"] == pytest.approx(0.38, abs=0.005) and held["limit"] == 0.5
    assert any("stays at 0.38" in n and "end stop" in n for n in d["spec"]["data"]["notes"])
    assert d["spec"]["verdict"] == "unexplained_discrepancy"
    assert any("stays at 0.38" in c for c in d["spec"]["unexplained"]["record_causes"])
    assert d["real"]["data"]["held_at_extreme"] == {}
    assert d["real"]["verdict"] == "no_significant_discrepancy"
    # a prismatic joint's notes and report speak metres
    html = (tmp_path / "rep_spec" / "report.html").read_text()
    assert "lift: position noise" in html and " mm, fit ceiling" in html and "mrad" not in html
    assert any(n.startswith("lift: the record starts at 0.2") and " m (+-" in n and "rad" not in n
               for n in d["spec"]["data"]["notes"])
    # `fit` on the same log says it too (in its output and its --json)
    proc = cli("fit", "--robot", tmp_path / "spec", tmp_path / "log.csv", "--out", tmp_path / "p.toml", "--json",
               *reading)
    assert proc.returncode == 0, proc.stderr
    assert any("stays at 0.38" in n and "end stop" in n for n in json.loads(proc.stdout)["notes"])


def test_a_joint_without_limits_in_the_spec_is_said_to_have_none():
    t, y, u = p_loop()
    f = find(t, y, u, limits=(-math.inf, math.inf))
    assert f is not None and f["limit"] is None
    assert "the spec has no upper limit" in H.note("swing", f, "rad") and json.dumps(f)
