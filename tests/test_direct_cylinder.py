"""A cylinder acting directly on a prismatic joint: statics, motion, energy, reference solver, effects
and the configuration errors (tests/data/lift: a 120 kg carriage on a vertical 0..0.5 m slide)."""

import math
import shutil

import numpy as np
import pytest

from sim_core.bench import prbs_all_joints
from sim_core.energy import balance, stored_energy, with_ledger
from sim_core.kernel import layout as L
from sim_core.model.spec import SpecError, load_robot
from sim_core.plant import Plant
from sim_core.reference import solve_reference
from sim_core.simulator import Simulator

from conftest import ROOT

LIFT = ROOT / "tests" / "data" / "lift"
G = 9.81


@pytest.fixture(scope="module")
def lift():
    return Plant.from_robot(LIFT / "robot.toml")


def _areas(plant):
    cyl = plant.spec.joint("lift").components["cylinder"]
    return cyl.area_a, cyl.area_b


def test_hydraulic_lock_holds_the_load_and_the_pressures_carry_its_weight(lift):
    """Zero command: the carriage stays put and p_A A_A - p_B A_B = m g (no motion, so no seal friction)."""
    ctx = lift.create_context()
    t = np.arange(0.0, 1.0001, 0.01)
    traj = Simulator(ctx).run(t, np.zeros((t.size, 1)))
    assert np.ptp(traj.q[:, 0]) < 1e-4, f"lock drifted {np.ptp(traj.q[:, 0]) * 1e3:.3f} mm"
    aa, ab = _areas(lift)
    force = traj.act[-1, 0, L.YA_P_A] * aa - traj.act[-1, 0, L.YA_P_B] * ab
    assert force == pytest.approx(120.0 * G, rel=0.01)


def test_positive_command_lifts_at_the_speed_the_valve_flow_allows(lift):
    """A positive command raises the carriage, a negative one lowers it; the rising speed is the
    meter-in flow over the cap area, bounded by the valve's flow at full supply drop."""
    ctx = lift.create_context()
    t = np.arange(0.0, 1.6001, 0.002)
    U = np.where(t < 0.8, 6.0, -6.0)[:, None]
    traj = Simulator(ctx).run(t, U)
    v = traj.qd[:, 0]
    rising, lowering = v[(t > 0.4) & (t < 0.75)], v[(t > 1.2) & (t < 1.55)]
    assert rising.min() > 0.0 and lowering.max() < 0.0
    spec = lift.spec
    valve = spec.joint("lift").components["valve"]
    opening = min(1.0, 6.0 * spec.get("joints.lift.amplifier.gain") * spec.get("joints.lift.spool.gain"))
    q_max = opening * valve["rated_flow"] * math.sqrt(spec.get("supply.pressure") / valve["rated_pressure_drop"])
    aa, _ = _areas(lift)
    assert rising.mean() < q_max / aa            # cannot beat the flow at the full supply drop
    assert rising.mean() > 0.3 * q_max / aa      # and the drop left after lifting 1.2 kN is most of it
    # chamber A's continuity at the steady rise: valve flow = A_A v (the oil barely compresses)
    k = (t > 0.5) & (t < 0.75)
    q_a = traj.act[k, 0, L.YA_Q_A]
    assert np.mean(q_a) == pytest.approx(aa * rising.mean(), rel=0.02)


@pytest.mark.slow
def test_energy_balance_closes_on_the_direct_cylinder(lift):
    ctx = lift.create_context()
    t, U = prbs_all_joints(lift.spec, 3.0, amplitude=5.0, seed=2)
    with_ledger(ctx)
    e0 = stored_energy(ctx)
    Simulator(ctx).run(t, U)
    b = balance(ctx, e0)
    assert b["supply"] > 10.0 and abs(b["actuator_work"]) > 1.0
    assert b["relative_residual"] < 1e-4, b
    assert b["mechanical_relative_residual"] < 3e-3, b


@pytest.mark.slow
def test_fixed_step_matches_radau_on_the_direct_cylinder(lift):
    t, U = prbs_all_joints(lift.spec, 2.0, amplitude=5.0, seed=5)
    q_ref, _ = solve_reference(lift.create_context(), t, U, method="Radau", rtol=1e-8)
    traj = Simulator(lift.create_context()).run(t, U)
    assert np.ptp(traj.q[:, 0]) > 0.02
    rms = math.sqrt(np.mean((traj.q[:, 0] - q_ref[:, 0]) ** 2))
    assert rms < 5e-4, f"{rms * 1e3:.3f} mm RMS"


@pytest.mark.parametrize("name,params", [
    ("backlash", {"width": 0.004}),                    # m on a prismatic joint
    ("joint_compliance", {"frequency": 8.0}),
    ("coulomb_friction", {"torque": 4000.0, "smoothing_velocity": 0.002}),  # N, m/s
    ("sensor_offset", {"offset": 0.01}),               # m
    ("sensor_gain", {}),
    ("leakage", {}),
    ("deadband", {"width": 1.0}),
    ("area_ratio", {}),
])
def test_bank_effects_act_on_the_direct_cylinder(lift, name, params):
    """Every effect that applies to a linear actuator runs on it and changes the record."""
    t, U = prbs_all_joints(lift.spec, 1.5, rate=200.0, amplitude=4.0, seed=1)
    base = Simulator(lift.create_context()).run(t, U)
    spec = lift.spec.copy()
    spec.enable_effect(name, "lift", **params)
    traj = Simulator(lift.create_context(spec)).run(t, U)
    y0, y1 = base.column("lift", L.YA_ANGLE), traj.column("lift", L.YA_ANGLE)
    assert np.all(np.isfinite(y1))
    assert np.max(np.abs(y1 - y0)) > 5e-4, f"{name} left the measured position unchanged"


def test_payload_is_a_mass_on_the_slide(lift):
    """A 30 kg payload raises the holding force by 30 g N."""
    spec = lift.spec.copy()
    spec.enable_effect("payload", "lift", mass=30.0)
    ctx = lift.create_context(spec)
    t = np.arange(0.0, 1.0001, 0.01)
    traj = Simulator(ctx).run(t, np.zeros((t.size, 1)))
    aa, ab = _areas(lift)
    force = traj.act[-1, 0, L.YA_P_A] * aa - traj.act[-1, 0, L.YA_P_B] * ab
    assert force == pytest.approx(150.0 * G, rel=0.01)


def _edited_rig(tmp_path, old, new):
    d = tmp_path / "rig"
    shutil.copytree(LIFT, d)
    text = (d / "robot.toml").read_text()
    assert old in text
    (d / "robot.toml").write_text(text.replace(old, new))
    return d / "robot.toml"


def test_a_cylinder_with_mounts_on_a_prismatic_joint_is_refused(tmp_path):
    path = _edited_rig(tmp_path, 'linkage = "direct"', 'base_mount = [0.0, 0.1, 0.0]\nrod_mount = [0.0, 0.1, 0.3]')
    with pytest.raises(SpecError, match=r"joints\.lift.*prismatic.*linkage = 'direct'"):
        load_robot(path)


def test_a_direct_cylinder_on_a_revolute_joint_is_refused():
    spec = load_robot("hydrolek")
    data_error = None
    try:
        spec.set("joints.j2.cylinder.linkage", "direct")
        spec.validate_structure()
    except Exception as exc:   # either the mounts or the joint type is named
        data_error = str(exc)
    assert data_error is not None and "j2" in data_error and ("revolute" in data_error or "mounts" in data_error)


def test_a_stroke_shorter_than_the_joint_range_is_refused(tmp_path):
    path = _edited_rig(tmp_path, 'linkage = "direct"', 'linkage = "direct"\nstroke = 0.3')
    with pytest.raises(SpecError, match=r"joints\.lift.*stroke"):
        load_robot(path)


def test_an_effect_that_cannot_apply_names_the_effect_and_the_joint(plants):
    spec = plants("harvester").spec.copy()
    with pytest.raises(Exception, match=r"area_ratio.*swing|swing.*area_ratio|applies to cylinder.*swing"):
        spec.enable_effect("area_ratio", "swing")
