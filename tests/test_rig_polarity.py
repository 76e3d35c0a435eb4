"""A rig wired the other way round from its spec, the user's way: ``rig new cylinder`` -> a
closed-loop log -> ``import`` -> ``diagnose``.

The log is the clean cylinder rig's (valve +20 %, supply -15 %, start off, 50 Hz, jitter, sensor
volts), then either its command column is written with the opposite sign (the valve's leads swapped
against the spec) or its position sensor reads the other way round with its own offset (``9.6 V -
v``: falling volts as the load rises). No effect of the bank reverses a sign: the verdict is
unexplained, and the report names which reversal explains the record; following its advice gives a
clean diagnosis.
"""

import json

import numpy as np
import pytest

from conftest import run_cli
from rig_records import closed_loop_record, write_headerless
from sim_core.model.spec import load_robot


@pytest.fixture(scope="module")
def rig_log(tmp_path_factory):
    root = tmp_path_factory.mktemp("polarity")
    run_cli("rig", "new", "cylinder", "--out", root / "rig", check=True)
    spec = load_robot(root / "rig")
    j = spec.joint_names[0]
    i = spec.tree.index(spec.joint(j).dof)
    span = float(spec.tree.upper[i] - spec.tree.lower[i])
    off = {f"joints.{j}.valve.rated_flow": 1.2, "supply.pressure": 0.85}
    rows, _ = closed_loop_record(root / "rig", hidden=None, off=off, seed=5, duration=60.0, start_offset=0.05 * span)
    return root, j, np.asarray(rows, float)


def _diagnose(cli, root, j, rows, name, command_unit=""):
    write_headerless(rows, root / f"{name}.csv")
    cli("import", root / f"{name}.csv", "--robot", root / "rig", "--out", root / f"{name}_rec.csv", "--no-header",
        "--column", "time=0", "--column", f"q_{j}=1:sensor_volts", "--column", f"u_{j}=2{command_unit}", check=True)
    proc = cli("diagnose", "--robot", root / "rig", root / f"{name}_rec.csv", "--report", root / f"{name}_rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    return json.loads((root / f"{name}_rep" / "diagnosis.json").read_text()), proc.stdout


def _reversal_named(d, j, named, other):
    """The record moves against its command, the reversal ``named`` (a fit key) explains it by 20
    points over the record as is and over the ``other`` reversal; returns the cause said."""
    assert d["verdict"] == "unexplained_discrepancy"
    e = d["unexplained"]["polarity"]["joints"][j]
    assert e["reversed"] and e["record"]["correlation"] < 0 < e["model"]["correlation"]
    assert e[named] > e["fit"] + 20 and e[named] > e[other] + 20
    return d["unexplained"]["record_causes"][0]


def test_a_valve_wired_the_other_way_is_named_and_reading_the_command_reversed_fixes_it(cli, rig_log):
    root, j, rows = rig_log
    swapped = rows.copy()
    swapped[:, 2] = -swapped[:, 2]
    d, printed = _diagnose(cli, root, j, swapped, "swapped")
    cause = _reversal_named(d, j, "fit_command_reversed", "fit_position_mirrored")
    assert "command reversed explains it" in cause and f"u_{j}=SOURCE:*-1" in cause
    assert "in the record: " in printed and "command reversed explains it" in printed
    # the advice, followed: the same log read with the command reversed is clean
    fixed, _ = _diagnose(cli, root, j, swapped, "swapped_fixed", command_unit=":*-1")
    assert fixed["verdict"] == "no_significant_discrepancy", fixed["unexplained"]


def test_a_sensor_reading_the_other_way_is_named_with_its_gain_reversed(cli, rig_log):
    root, j, rows = rig_log
    mirrored = rows.copy()
    mirrored[:, 1] = 9.6 - mirrored[:, 1]          # the reading falls as the load rises, 0.4 V short of the span
    d, _ = _diagnose(cli, root, j, mirrored, "mirrored")
    cause = _reversal_named(d, j, "fit_position_mirrored", "fit_command_reversed")
    a = load_robot(root / "rig").get(f"joints.{j}.sensor.A")
    assert "position mirrored explains it" in cause and f"joints.{j}.sensor.A = {-a:.6g}" in cause

