"""Spec errors through the real CLI: one line naming the file, the line, the key and what was expected,
exit status 2, no traceback; --robot resolution; the [estimated] table."""

import re
import shutil

import pytest

from sim_core.model.spec import SpecError, load_robot

from conftest import ROOT

LIFT = ROOT / "tests" / "data" / "lift"


def _rig(tmp_path, edit=None, urdf_edit=None, name="rig"):
    d = tmp_path / name
    shutil.copytree(LIFT, d)
    if edit:
        text = (d / "robot.toml").read_text()
        new = edit(text)
        assert new != text
        (d / "robot.toml").write_text(new)
    if urdf_edit:
        text = (d / "lift.urdf").read_text()
        new = urdf_edit(text)
        assert new != text
        (d / "lift.urdf").write_text(new)
    return d


def _line_of(path, needle):
    return next(i for i, ln in enumerate(path.read_text().splitlines(), 1) if needle in ln)


def _error(cli, robot, *cmd):
    r = cli(*(cmd or ("robots",)), "--robot", robot)
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    m = re.match(r"^hydrohil \S+: error: (?P<file>[^:]+?)(?::(?P<line>\d+))?: (?P<rest>.*)$", lines[0])
    assert m, lines[0]
    return m.group("file"), (int(m.group("line")) if m.group("line") else None), m.group("rest")


def test_toml_syntax_error_names_file_and_line(cli, tmp_path):
    d = _rig(tmp_path, lambda t: t.replace("bore = 0.05", "bore = 0.05 0.06"))
    f, line, rest = _error(cli, d)
    assert f.endswith("rig/robot.toml") and line == _line_of(d / "robot.toml", "bore = 0.05 0.06")
    assert rest.startswith("invalid TOML")


def test_unknown_key_lists_the_known_ones(cli, tmp_path):
    d = _rig(tmp_path, lambda t: t.replace("bore = 0.05\n", "bore = 0.05\nboer = 0.05\n"))
    f, line, rest = _error(cli, d)
    assert line == _line_of(d / "robot.toml", "boer = ")
    assert rest.startswith("joints.lift.cylinder.boer: unknown parameter(s) boer; known: bore, rod_diameter")


def test_unknown_table_and_joint_key(cli, tmp_path):
    d = _rig(tmp_path, lambda t: t + "\n[pump]\npressure = 1e7\n")
    f, line, rest = _error(cli, d)
    assert line == _line_of(d / "robot.toml", "[pump]")
    assert rest.startswith("pump: unknown table(s) pump; known: robot, integrator")
    d = _rig(tmp_path, lambda t: t.replace("initial_position = 0.2", "initial_position = 0.2\nvalv = 1"), name="b")
    f, line, rest = _error(cli, d)
    assert line == _line_of(d / "robot.toml", "valv = 1")
    assert rest.startswith("joints.lift.valv: unknown key(s) valv; known: dof, initial_position")


@pytest.mark.parametrize("old,new,key,needle,expect", [
    ("bore = 0.05", "bore = 50", "joints.lift.cylinder.bore", "bore = 50",
     "50 m is outside [0.005, 1] (looks like mm: 50 mm = 0.05 m)"),
    ("pressure = 14.0e6", "pressure = 140", "supply.pressure", "pressure = 140",
     "140 Pa is outside [100000, 6e+07] (looks like bar: 140 bar = 1.4e+07 Pa)"),
    # a value from [defaults.valve] is reported at its line under [defaults.valve]
    ("rated_flow = 2.0e-4", "rated_flow = 12.0", "joints.lift.valve.rated_flow", "rated_flow = 12.0",
     "12 m^3/s is outside [1e-07, 0.1] (looks like L/min: 12 L/min = 0.0002 m^3/s)"),
    ("rod_diameter = 0.028", "rod_diameter = 0.06", "joints.lift.cylinder.rod_diameter", "rod_diameter = 0.06",
     "must be smaller than the bore"),
])
def test_value_out_of_range_names_key_unit_and_line(cli, tmp_path, old, new, key, needle, expect):
    d = _rig(tmp_path, lambda t: t.replace(old, new))
    f, line, rest = _error(cli, d)
    assert line == _line_of(d / "robot.toml", needle)
    assert rest == f"{key}: {expect}"


def test_toml_joint_missing_from_the_urdf(cli, tmp_path):
    d = _rig(tmp_path, lambda t: t.replace("[joints.lift", "[joints.lifter"))
    f, line, rest = _error(cli, d)
    assert line == _line_of(d / "robot.toml", "[joints.lifter]")
    assert rest == "joints.lifter: the URDF (lift.urdf) has no moving joint 'lifter'; its moving joints: lift"


def test_urdf_driven_joint_without_toml_entry(cli, tmp_path):
    extra = ('  <link name="tool"><inertial><mass value="5.0"/>'
             '<inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>\n'
             '  <joint name="clamp" type="prismatic">\n    <parent link="carriage"/><child link="tool"/>\n'
             '    <axis xyz="1 0 0"/><limit lower="0" upper="0.1" effort="2000" velocity="0.1"/>\n  </joint>\n</robot>')
    d = _rig(tmp_path, urdf_edit=lambda t: t.replace("</robot>", extra))
    f, line, rest = _error(cli, d)
    assert f.endswith("rig/lift.urdf") and line == _line_of(d / "lift.urdf", '<joint name="clamp"')
    assert rest.startswith("joint 'clamp': has effort 2000 (a driven joint) but robot.toml has no [joints.clamp]")
    assert "[passive.clamp]" in rest
    # declared passive, it loads
    (d / "robot.toml").write_text((d / "robot.toml").read_text() + "\n[passive.clamp]\ninitial_position = 0.05\n")
    assert cli("robots", "--robot", d).returncode == 0


def test_the_same_error_through_other_commands(cli, tmp_path):
    d = _rig(tmp_path, lambda t: t.replace("bore = 0.05", "bore = 50"))
    line = _line_of(d / "robot.toml", "bore = 50")
    for cmd in (("excite", "--joint", "lift", "--out", str(tmp_path / "x.csv")),
                ("fit", str(tmp_path / "x.csv"), "--out", str(tmp_path / "fit.toml"))):
        f, ln, rest = _error(cli, d, *cmd)
        assert ln == line and rest.startswith("joints.lift.cylinder.bore: 50 m is outside"), cmd


@pytest.mark.parametrize("robot,expect", [
    ("nosuch", "unknown robot 'nosuch'; built-in robots: harvester, hydrolek, mars_nd"),
    ("{tmp}", "holds no robot.toml"),
    ("{tmp}/lift.urdf", "is a URDF; --robot takes the robot.toml beside it"),
    ("{tmp}/none/robot.toml", "no such file or directory"),
])
def test_robot_resolution_errors(cli, tmp_path, robot, expect):
    shutil.copy(LIFT / "lift.urdf", tmp_path / "lift.urdf")
    r = cli("robots", "--robot", robot.format(tmp=tmp_path))
    assert r.returncode == 2 and "Traceback" not in r.stderr and expect in r.stderr, r.stderr


def test_estimated_table_two_shapes_and_errors(cli, tmp_path):
    quoted = '\n[estimated]\n"joints.lift.valve.rated_flow" = [1e-4, 4e-4]\n"supply.pressure" = [1.0e7, 1.6e7]\n' \
             '"effects.payload.lift.mass" = [0.0, 50.0]\n'
    nested = '\n[estimated.joints.lift.valve]\nrated_flow = [1e-4, 4e-4]\n[estimated.supply]\npressure = [1.0e7, 1.6e7]\n' \
             '[estimated.effects.payload.lift]\nmass = [0.0, 50.0]\n'
    payload = '\n[[effects]]\nname = "payload"\njoint = "lift"\nmass = 20.0\n'
    a = load_robot(_rig(tmp_path, lambda t: t + payload + quoted, name="a"))
    b = load_robot(_rig(tmp_path, lambda t: t + payload + nested, name="b"))
    want = {"joints.lift.valve.rated_flow": (1e-4, 4e-4), "supply.pressure": (1.0e7, 1.6e7),
            "effects.payload.lift.mass": (0.0, 50.0)}
    assert a.estimated == want and b.estimated == want
    assert load_robot(LIFT).estimated == {}
    # 'true': estimated without a range: a decade either way of a positive value, +-max(|v|, 1) otherwise
    c = load_robot(_rig(tmp_path, lambda t: t + '\n[estimated]\n"joints.lift.valve.rated_flow" = true\n'
                                             '"joints.lift.sensor.B" = true\n', name="c"))
    assert c.estimated["joints.lift.valve.rated_flow"] == pytest.approx((2e-5, 2e-3))
    assert c.estimated["joints.lift.sensor.B"] == (-1.0, 1.0)
    cases = [
        ('"joints.lift.valve.rated_flow" = [1e-3, 2e-3]', "the value 0.0002 m^3/s lies outside its estimated range"),
        ('"joints.lift.valve.rated_flo" = [1e-4, 4e-4]', "unknown parameter 'rated_flo'; known: rated_flow"),
        ('"joints.lift.valve.rated_flow" = [4e-4, 1e-4]', "lower 0.0004 must be below upper 0.0001"),
        ('"joints.lift.valve.rated_flow" = [0.0, 4e-4]', "leaves the parameter's bounds [1e-07, 0.1]"),
        ('"joints.lift.hose.flow_regime" = [0.0, 1.0]', "not a number parameter"),
        ('"effects.deadband.lift.width" = [0.0, 1.0]', "no such effect enabled"),
        # a prismatic joint's sensor gain reads in m/V, as the joint's position does in m
        ('"joints.lift.sensor.A" = [-0.06, -0.04]', "lies outside its estimated range [-0.06, -0.04] m/V"),
    ]
    for i, (entry, expect) in enumerate(cases):
        d = _rig(tmp_path, lambda t: t + "\n[estimated]\n" + entry + "\n", name=f"e{i}")
        f, line, rest = _error(cli, d)
        assert line == _line_of(d / "robot.toml", entry), entry
        key = entry.split(" = ")[0]
        assert rest.startswith(f"estimated.{key}: ") and expect in rest, rest
    with pytest.raises(SpecError, match="estimated"):
        load_robot(_rig(tmp_path, lambda t: t + "\n[estimated]\nx = 3\n", name="x"))


def test_urdf_problems_name_the_urdf(cli, tmp_path):
    d = _rig(tmp_path, lambda t: t.replace('urdf = "lift.urdf"', 'urdf = "lfit.urdf"'))
    f, line, rest = _error(cli, d)
    assert line == _line_of(d / "robot.toml", 'urdf = "lfit.urdf"') and rest.startswith("robot.urdf: no such file")
    d = _rig(tmp_path, urdf_edit=lambda t: t.replace("</robot>", "<link"), name="m")
    f, line, rest = _error(cli, d)
    assert f.endswith("m/lift.urdf") and rest.startswith("malformed URDF")


def test_cylinder_mounts_that_do_not_extend_over_the_range_are_refused():
    """The mounting geometry is checked (and cached) per set of mounts: a rod eye on the axis or behind
    it is refused with the cylinder's path, and the valid mounts are accepted again afterwards."""
    spec = load_robot("hydrolek")
    good = spec.get("joints.j2.cylinder.rod_mount")
    for bad in ([0.0, 0.0, 0.0], [-0.2, 0.0, 0.0]):
        s = spec.copy()
        with pytest.raises(SpecError, match=r"joints\.j2\.cylinder: positive joint motion must extend the cylinder") as err:
            s.set("joints.j2.cylinder.rod_mount", bad)
        arm = float(re.search(r"moment arm falls to (\S+) m", str(err.value)).group(1))
        assert arm <= 1e-4, str(err.value)
    s = spec.copy()
    s.set("joints.j2.cylinder.rod_mount", list(good))
    assert s.get("joints.j2.cylinder.rod_mount") == spec.get("joints.j2.cylinder.rod_mount")
