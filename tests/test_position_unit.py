"""A position logged in another unit than it is read in (identification/outside_range.py, the import's
note): the rules on synthetic figures, then the user's way: the rotary rig's closed-loop log with its
angle logged in degrees and read as radians -> ``import`` notes the unit that fits -> ``diagnose``
names the unit before the valve -> the advice followed gives a clean diagnosis.

Expected values come from the logs written here (the unit put in), not from the code under test."""

import math

import numpy as np
import pytest

from conftest import run_cli
from rig_records import closed_loop_record, diagnose_log, write_headerless
from sim_core.identification.outside_range import MAJORITY, cause, named
from sim_core.ingest.joint_range import INSIDE_SHARE, MARGIN, SPAN_SHARE, readings_inside, share
from sim_core.ingest.units import parse_unit

DEG = {"deg": parse_unit("deg", "angle", column="q")}


def test_a_reading_is_suggested_where_it_puts_the_values_inside_the_range_and_spans_part_of_it():
    y = np.linspace(-60.0, 60.0, 201)                                 # degrees, a +-1.5 rad joint
    assert readings_inside(y, DEG, -1.5, 1.5) == ["deg"]
    assert readings_inside(y * 3.0, DEG, -1.5, 1.5) == []      # still outside read as deg
    small = np.linspace(0.0, 0.5 * SPAN_SHARE * 3.0 / DEG["deg"].scale, 201)
    assert readings_inside(small, DEG, -1.5, 1.5) == []       # inside, but spans too little to tell
    y[: int(len(y) * (1 - INSIDE_SHARE)) + 2] = 500.0                  # more than 1 % still outside
    assert readings_inside(y, DEG, -1.5, 1.5) == []


def test_the_share_outside_counts_beyond_the_margin_and_a_majority_names_it():
    y = np.array([-1.5 - 0.5 * MARGIN, 1.5 + 0.5 * MARGIN, 1.5 + 2 * MARGIN, 0.0])
    assert share(y, -1.5, 1.5) == pytest.approx(0.25)                 # an end-stop overshoot is not outside
    assert share(y, -math.inf, math.inf) == 0.0
    assert named(1.1 * MAJORITY) and not named(0.9 * MAJORITY)


def test_the_cause_names_the_range_the_span_and_the_unit_that_fits():
    y = np.degrees(np.linspace(-1.0, 1.2, 101))
    said = cause("swing", share(y, -1.5, 1.5), y, -1.5, 1.5, "rad")
    assert "outside the joint's range [-1.5, 1.5] rad (the record spans -57.3 .. 68.75 rad)" in said
    assert "`--column q_swing=SOURCE:deg`" in said
    far = np.linspace(0.0, 1e5, 101)                                   # read as mm still 100 m long
    assert "SOURCE:" not in cause("lift", 1.0, far, 0.0, 0.5, "m")


# ---- the user's way --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def degree_log(tmp_path_factory):
    """The rotary rig (valve -10 %, supply +10 %, start off) under its P controller, its angle logged in
    degrees (the sensor model applied by the logger) instead of sensor volts."""
    root = tmp_path_factory.mktemp("degrees")
    run_cli("rig", "new", "rotary", "--out", root / "rig", check=True)
    rows, spec = closed_loop_record(root / "rig", hidden=None, seed=31, start_offset=0.03,
                                    off={"joints.swing.valve.rated_flow": 0.9, "supply.pressure": 1.1})
    rows = np.asarray(rows, float)
    A, B = spec.get("joints.swing.sensor.A"), spec.get("joints.swing.sensor.B")
    rows[:, 1] = np.degrees(A * rows[:, 1] + B)
    write_headerless(rows, root / "log.csv")
    return root


def test_import_notes_the_unit_under_which_the_angle_lies_inside_its_range(cli, degree_log):
    proc = cli("import", "--robot", degree_log / "rig", degree_log / "log.csv", "--no-header", "--column", "time=0",
               "--column", "q_swing=1", "--column", "u_swing=2", "--out", degree_log / "as_rad.csv")
    assert proc.returncode == 0, proc.stderr
    assert "outside the joint's range" in proc.stdout and "(--column q_swing=1:deg)" in proc.stdout


def test_an_angle_in_degrees_read_as_radians_is_named_before_the_valve_and_reading_it_right_fixes_it(cli, degree_log):
    d, printed = diagnose_log(cli, degree_log, "as_rad", "swing", position_unit="")
    assert d["verdict"] == "unexplained_discrepancy"
    assert d["data"]["outside_range_share"]["swing"] > MAJORITY
    first = d["unexplained"]["record_causes"][0]
    assert "outside the joint's range" in first and "`--column q_swing=SOURCE:deg`" in first
    assert "command_scale" not in d["unexplained"]            # the speeds are in degrees, not the valve's doing
    assert "SOURCE:deg`" in printed
    fixed, _ = diagnose_log(cli, degree_log, "as_deg", "swing", position_unit=":deg")
    assert fixed["verdict"] == "no_significant_discrepancy", fixed.get("unexplained")
    assert fixed["data"]["outside_range_share"]["swing"] == 0.0
