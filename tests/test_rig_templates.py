"""hydrohil rig new: every template (and the cylinder vertical, horizontal and at 30 deg) writes a rig
that loads, runs 2 s stably, moves positive for a positive command and holds its load at zero command;
the written files document every parameter; --set edits keys and knobs; robots --robot describes it."""

import json
import math
import re
import tomllib

import numpy as np
import pytest

from sim_core.components.base import Component
from sim_core.kernel import layout as L
from sim_core.model.spec import SECTIONS, load_robot
from sim_core.plant import Plant
from sim_core.simulator import Simulator

G = 9.81
CASES = {
    "cylinder_vertical": ("cylinder", ["orientation=vertical"], 90.0),
    "cylinder_horizontal": ("cylinder", ["orientation=horizontal"], 0.0),
    "cylinder_30deg": ("cylinder", ["incline_deg=30"], 30.0),
    "boom": ("boom", [], None),
    "rotary": ("rotary", [], None),
}


@pytest.fixture(scope="module")
def rigs(tmp_path_factory):
    from conftest import run_cli

    root = tmp_path_factory.mktemp("rigs")
    out = {}
    for case, (template, sets, _) in CASES.items():
        args = ["rig", "new", template, "--out", root / case]
        for s in sets:
            args += ["--set", s]
        r = run_cli(*args, check=True)
        assert "warning" not in r.stderr, r.stderr          # the templates' actuators carry their loads
        out[case] = root / case
    return out


def _run(plant, u, duration=2.0, dt=0.01, t_step=0.2):
    t = np.arange(0.0, duration + dt / 2, dt)
    U = np.where(t >= t_step, u, 0.0)[:, None]
    return t, Simulator(plant.create_context()).run(t, U)


@pytest.mark.parametrize("case", list(CASES))
def test_rig_loads_runs_moves_positive_and_holds(rigs, case):
    template, _, incline = CASES[case]
    plant = Plant.from_robot(rigs[case])
    assert plant.spec.source == rigs[case] / "robot.toml"
    (joint,) = plant.joint_names
    i = plant.tree.index(plant.spec.joint(joint).dof)
    assert bool(plant.tree.is_prismatic(i)) == (template == "cylinder")
    lo, hi = float(plant.tree.lower[i]), float(plant.tree.upper[i])
    span = hi - lo

    t, still = _run(plant, 0.0)
    q0 = still.q[0, 0]
    assert np.all(np.isfinite(still.q)) and np.all(np.isfinite(still.act))
    # hydraulic lock: a closed valve holds the load (only the oil's compression, micrometres or microradians)
    assert np.max(np.abs(still.q[:, 0] - q0)) < 1e-3 * span, f"drifted {np.max(np.abs(still.q[:, 0] - q0)):.3g}"

    for u in (4.0, -4.0):
        t, tr = _run(plant, u)
        q = tr.q[:, 0]
        assert np.all(np.isfinite(q)) and np.all(np.isfinite(tr.qd))
        assert np.all((q > lo - 0.02 * span) & (q < hi + 0.02 * span)), "left the joint range (end stops)"
        moved = q[-1] - q0
        assert math.copysign(1.0, moved) == math.copysign(1.0, u), f"command {u} V moved {moved:+.3g}"
        assert abs(moved) > 0.05 * span, f"command {u} V moved only {moved:+.3g} of a {span:g} range"
        # stable: no growing oscillation once moving (speed stays within what the valve can pass)
        assert np.max(np.abs(tr.qd[:, 0])) < 10.0 * span

    # after a move the closed valve locks the load where it stopped (against gravity where there is one)
    t = np.arange(0.0, 2.0 + 0.005, 0.01)
    U = np.where((t >= 0.2) & (t < 0.7), 4.0, 0.0)[:, None]
    tr = Simulator(plant.create_context()).run(t, U)
    q = tr.q[:, 0]
    assert q[-1] - q0 > 0.02 * span
    # no creep (the mean stays put) and any ringing of the oil column dies away
    early, late = q[(t >= 1.0) & (t < 1.5)], q[t >= 1.5]
    assert abs(late.mean() - early.mean()) < 1e-3 * span, f"crept {late.mean() - early.mean():.3g}"
    assert np.ptp(late) <= np.ptp(q[(t >= 0.75) & (t < 1.0)]) + 1e-9
    assert np.ptp(late) < 0.02 * span

    if incline is not None:
        # the pressures carry the weight along the slide: (carriage + load) g sin(incline)
        cyl = plant.spec.joint(joint).components["cylinder"]
        force = still.act[-1, 0, L.YA_P_A] * cyl.area_a - still.act[-1, 0, L.YA_P_B] * cyl.area_b
        mass = float(plant.tree.mass[i]) + plant.spec.effects[0].params["mass"]
        weight = mass * G
        assert force == pytest.approx(weight * math.sin(math.radians(incline)), abs=0.01 * weight)


def _assignments(text):
    """(table, key, comment) of every 'key = value' line."""
    table, out = "", []
    for line in text.splitlines():
        s = line.strip()
        m = re.match(r"^\[\[?([^\]]+)\]\]?$", s)
        if m:
            table = m.group(1)
            continue
        m = re.match(r'^("[^"]+"|[A-Za-z0-9_]+)\s*=\s*(.*)$', s)
        if m:
            comment = m.group(2).split("#", 1)[1].strip() if "#" in m.group(2) else ""
            out.append((table, m.group(1), comment))
    return out


@pytest.mark.parametrize("case", ["cylinder_vertical", "boom", "rotary"])
def test_every_parameter_is_written_with_unit_typical_range_and_how_to_measure(rigs, case):
    d = rigs[case]
    text = (d / "robot.toml").read_text()
    data = tomllib.loads(text)
    for table, key, comment in _assignments(text):
        if table == "robot" or (table == "effects" and key in ("name", "joint")):
            continue                                  # identifiers, not parameters
        if table == "estimated":
            assert ";" in comment and comment.split(";")[0].strip(), f"[estimated] {key}: no unit in {comment!r}"
            continue
        parts = [p.strip() for p in comment.split(";")]
        assert len(parts) >= 3, f"[{table}] {key}: comment {comment!r} lacks unit; typical range; how to find it"
        assert parts[1].startswith("typical") or key in ("linkage", "flow_regime", "type"), f"[{table}] {key}: {comment!r}"
    # every parameter of every component is written out (the user sees them all), except the direct
    # cylinder's optional geometry (commented) and a direct cylinder's mounts
    (jname, jt), = data["joints"].items()
    for sec, cls in SECTIONS.items():
        if sec not in jt:
            continue
        comp: type[Component] = cls
        expected = {p.name for p in comp.PARAMETERS}
        if sec == "cylinder":
            expected -= {"offset", "stroke"}          # defaults from the joint limits, written as comments
            if jt[sec]["linkage"] == "direct":
                expected -= {"base_mount", "rod_mount"}
        assert set(jt[sec]) == expected, f"{sec}: missing {expected - set(jt[sec])}"
    spec = load_robot(d)
    for sec in ("integrator", "fluid", "supply"):
        assert set(data[sec]) == {p.name for p in getattr(spec, sec).PARAMETERS}, sec
    # the URDF's masses and limits carry their unit, typical range and how to find them
    urdf = next(d.glob("*.urdf")).read_text()
    for tag, unit in (("<mass value", "kg"), ("<limit ", "m")):
        for m in re.finditer(re.escape(tag), urdf):
            comment = re.search(r"<!--(.*?)-->", urdf[m.end():], re.S).group(1)
            if "does not matter" in comment:          # a link fixed to the ground
                continue
            assert f"{unit};" in comment or f"{unit} " in comment, f"{tag}: no unit in {comment!r}"
            assert "typical" in comment, f"{tag}: no typical range in {comment!r}"


@pytest.mark.parametrize("case", list(CASES))
def test_estimated_parameters_and_ranges(rigs, case):
    spec = load_robot(rigs[case])
    (j,) = spec.joint_names
    act = spec.joint(j).kind
    expected = {"supply.pressure", f"joints.{j}.valve.rated_flow", f"joints.{j}.sensor.A", f"joints.{j}.sensor.B",
                f"joints.{j}.{act}.viscous_friction", f"effects.payload.{j}.mass"}
    assert set(spec.estimated) == expected
    for path, (lo, hi) in spec.estimated.items():
        value = spec.effects[0].params["mass"] if path.startswith("effects.") else spec.get(path)
        assert lo < hi and lo <= value <= hi, (path, value, lo, hi)


def test_set_edits_keys_in_place_and_knobs_follow(cli, tmp_path):
    d = tmp_path / "bench"
    r = cli("rig", "new", "cylinder", "--out", d, "--name", "test_bench",
            "--set", "joints.lift.hose.length=3.5", "--set", "joints.lift.cylinder.bore=0.063",
            "--set", "load_kg=250", "--set", "supply.pressure=1.8e7", "--set", "stroke=0.8",
            "--set", "joints.lift.valve.characteristic=[0.5, 0.3, 0.2]")
    assert r.returncode == 0, r.stderr
    assert (d / "test_bench.urdf").is_file()
    text = (d / "robot.toml").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("length ="))
    assert line.split("#")[0].strip() == "length = 3.5" and "typical" in line     # comment kept
    spec = load_robot(d)
    assert spec.name == "test_bench"
    assert spec.get("joints.lift.hose.length") == 3.5
    assert spec.get("joints.lift.cylinder.bore") == 0.063
    assert spec.get("joints.lift.valve.characteristic") == (0.5, 0.3, 0.2)
    assert spec.get("supply.pressure") == 1.8e7
    assert spec.get("supply.relief_pressure") > 1.8e7          # derived from the supply knob
    assert spec.effects[0].params["mass"] == 250.0
    lo, hi = spec.estimated["effects.payload.lift.mass"]
    assert lo <= 250.0 <= hi
    i = spec.tree.index("lift")
    assert spec.tree.upper[i] == pytest.approx(0.8)
    assert spec.get("joints.lift.sensor.A") == pytest.approx(0.08)     # 0.8 m over 10 V


def test_set_and_out_errors(cli, tmp_path):
    d = tmp_path / "r"
    r = cli("rig", "new", "cylinder", "--out", d, "--set", "joints.lift.valve.rated_flw=3e-4")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "joints.lift.valve.rated_flw" in r.stderr and "did you mean joints.lift.valve.rated_flow" in r.stderr
    assert "supply.pressure" in r.stderr and "incline_deg" in r.stderr          # lists the valid keys and knobs
    assert not d.exists()
    r = cli("rig", "new", "boom", "--out", d, "--set", "joints.boom.cylinder.bore=63")
    assert r.returncode == 2 and "joints.boom.cylinder.bore" in r.stderr and "mm" in r.stderr
    r = cli("rig", "new", "boom", "--out", d, "--set", "joints.boom.cylinder.rod_diameter=0.08")
    assert r.returncode == 2 and "rod_diameter" in r.stderr and "bore" in r.stderr
    r = cli("rig", "new", "cylinder", "--out", d, "--set", "orientation=sideways")
    assert r.returncode == 2 and "vertical, horizontal, incline" in r.stderr
    assert cli("rig", "new", "rotary", "--out", d).returncode == 0
    before = (d / "robot.toml").read_text()
    r = cli("rig", "new", "rotary", "--out", d, "--set", "load_kg=9")
    assert r.returncode == 2 and "--force" in r.stderr and (d / "robot.toml").read_text() == before
    assert cli("rig", "new", "rotary", "--out", d, "--set", "load_kg=9", "--force").returncode == 0
    assert load_robot(d).effects[0].params["mass"] == 9.0


def test_an_actuator_too_small_for_its_load_is_warned(cli, tmp_path):
    """A 10 kg, 0.6 m arm with 60 kg at its end needs (10 * 0.3 + 60 * 0.6) g = 382.6 N m; the vane
    actuator gives 2e-5 m^3/rad * (14 - 0.2) MPa = 276 N m: written, but warned."""
    r = cli("rig", "new", "rotary", "--out", tmp_path / "r", "--set", "load_kg=60")
    assert r.returncode == 0 and (tmp_path / "r" / "robot.toml").is_file()
    assert "warning: joints.swing: the load needs 382.6 N m" in r.stderr and "at most 276 N m" in r.stderr
    assert "could not lift" in r.stderr
    r = cli("rig", "new", "rotary", "--out", tmp_path / "r2", "--set", "load_kg=40")       # 264.9 N m: 96 %
    assert r.returncode == 0 and "264.9 N m at q = 0, 96 % of the 276 N m" in r.stderr and "crawl" in r.stderr
    r = cli("rig", "new", "rotary", "--out", tmp_path / "r3", "--set", "load_kg=30")       # 206 N m: fits
    assert r.returncode == 0 and "warning" not in r.stderr


def test_robot_is_named_by_name_directory_or_toml_path(cli, rigs):
    from sim_core.model.spec import ROBOTS_DIR

    outs = [json.loads(cli("robots", "--robot", r, "--json", check=True).stdout)
            for r in ("harvester", ROBOTS_DIR / "harvester", ROBOTS_DIR / "harvester" / "robot.toml")]
    assert outs[0] == outs[1] == outs[2] and outs[0]["builtin"]
    d = rigs["cylinder_30deg"]
    one = json.loads(cli("robots", "--robot", d, "--json", check=True).stdout)
    assert one == json.loads(cli("robots", "--robot", d / "robot.toml", "--json", check=True).stdout)
    (j,) = one["joints"]
    assert j["type"] == "prismatic" and j["q_unit"] == "m" and j["qd_unit"] == "m/s"
    assert j["actuator"]["kind"] == "cylinder" and j["actuator"]["linkage"] == "direct"
    assert j["sensor"]["A_unit"] == "m/V" and j["sensor"]["B_unit"] == "m"
    assert j["parameters"]["sensor"]["A"]["unit"] == "m/V"
    assert j["parameters"]["cylinder"]["bore"] == {"value": 0.05, "unit": "m"}
    assert j["limits"] == [0.0, 0.5] and [e["name"] for e in j["effects"]] == ["payload"]
    assert "joints.lift.valve.rated_flow" in one["estimated"] and not one["builtin"]
    assert one["estimated_units"]["joints.lift.sensor.A"] == "m/V"
    assert one["estimated_units"]["effects.payload.lift.mass"] == "kg"
    boom = json.loads(cli("robots", "--robot", rigs["boom"], "--json", check=True).stdout)
    assert boom["joints"][0]["type"] == "revolute" and boom["joints"][0]["sensor"]["A_unit"] == "rad/V"
    # the plain listing is unchanged: the built-in robots only
    listing = json.loads(cli("robots", "--json", check=True).stdout)
    assert [r["name"] for r in listing] == ["harvester", "hydrolek", "mars_nd"]
    assert set(listing[0]) == {"name", "description", "reference", "urdf", "joints", "passive_joints"}


def test_a_rig_directory_works_through_excite_and_simulate(cli, rigs, tmp_path):
    d = rigs["boom"]
    cli("excite", "--robot", d, "--joint", "boom", "--duration", "2", "--rate", "50", "--out", tmp_path / "in.csv",
        check=True)
    cli("simulate", "--robot", d / "robot.toml", "--input", tmp_path / "in.csv", "--out", tmp_path / "out.csv",
        check=True)
    header = (tmp_path / "out.csv").read_text().splitlines()[0].split(",")
    assert "q_boom" in header and "u_boom" in header


@pytest.mark.realtime
def test_serve_and_dbc_run_a_rig_directory(cli, rigs, tmp_path):
    """hydrohil serve --robot DIR: the engine runs the rig, REST commands move it, the CAN database is
    generated from its joints (also what 'hydrohil dbc --robot DIR' prints)."""
    import time

    import cantools

    from server_helpers import ServerProcess

    d = rigs["cylinder_vertical"]
    db = cantools.database.load_string(cli("dbc", "--robot", d, check=True).stdout, database_format="dbc")
    assert {"ValveCommand_lift", "JointFeedback_lift"} <= {m.name for m in db.messages}
    srv = ServerProcess(robot=str(d), can="socketcand", tmp_path=tmp_path)
    try:
        assert srv.rest.health()["robot"] == "cylinder_vertical"
        q0 = srv.rest.state()["joints"]["lift"]["angle"]       # the measured position, m on this slide
        srv.rest.set_voltages({"lift": 4.0})
        time.sleep(1.0)
        srv.rest.set_voltages({"lift": 0.0})
        assert srv.rest.state()["joints"]["lift"]["angle"] > q0 + 0.02
        assert srv.rest.parameters()["values"]["joints.lift.cylinder.bore"] == 0.05
        # the browser monitor finds the rig through 'view --robot DIR' (the server only names it)
        from web.links import LinkError, RemoteLink

        with pytest.raises(LinkError, match="--robot"):
            RemoteLink(srv.url)
        link = RemoteLink(srv.url, robot=str(d))
        try:
            assert link.spec.source == d / "robot.toml"
        finally:
            link.close()
    finally:
        assert srv.stop() == 0
