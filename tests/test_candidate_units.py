"""The units a candidate's parameters are reported in follow the joint (candidates.from_hints): the
effects state a revolute joint's ('N m', 'rad'), which on a prismatic joint read as a force and a
length. A cylinder rig's friction in 'N m' would tell its user a force of 1000 N is a torque."""

from pathlib import Path

import pytest

from sim_core.identification.candidates import bank
from sim_core.model.spec import load_robot

SLIDE = Path(__file__).resolve().parent / "data" / "import" / "slide"     # one prismatic joint


def units(robot, joint):
    spec = load_robot(robot)
    return {fp.key.split(".", 1)[1].replace(f".{joint}.", "."): fp.unit for c in bank(spec, [joint]) for fp in c.free}


@pytest.mark.parametrize("robot, joint, expected", [
    (SLIDE, None, {"coulomb_friction.torque": "N", "backlash.width": "m", "sensor_offset.offset": "m"}),
    ("hydrolek", "j2", {"coulomb_friction.torque": "N m", "backlash.width": "rad", "sensor_offset.offset": "rad"}),
])
def test_friction_and_lengths_in_the_joints_units(robot, joint, expected):
    spec = load_robot(robot)
    joint = joint or spec.joint_names[0]
    got = units(robot, joint)
    assert {k: got[k] for k in expected} == expected
    # what does not depend on the joint's kind stays as declared
    assert got["deadband.width"] == "V" and got["leakage.internal"] == "m^3/(s Pa)" and got["payload.mass"] == "kg"
