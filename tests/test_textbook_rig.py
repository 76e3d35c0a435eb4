"""Rigs HydroHIL did not simulate: the cylinder and boom templates against a textbook model written apart.

``tests/textbook_cylinder.py`` integrates Merritt's equations of a single-rod cylinder fed by a 4/3
proportional valve with SciPy, acting on a slide or raising a boom through its pins, from the
templates' parameter meanings alone (no sim_core code). Two checks: the kernel, given the same rig
and the same command, moves the joint as the textbook model does (each effect of the bank beside the
physical cause it stands for); and ``rig new`` -> ``import`` -> ``diagnose`` on the textbook rig's
closed-loop log (50 Hz, headerless, sensor volts, jittered, no pressures, nominal parameters 10-30 %
off, a start off the spec's) says what the textbook rig has that the template does not, and nothing
when it has nothing.
"""

import json

import numpy as np
import pytest

from sim_core.effects import EFFECTS

from rig_records import measured, write_headerless
from textbook_cylinder import BENCHES, SPOOL_GAIN_PER_VOLT, Bench, Rig, closed_loop_log


def _rig_dir(cli, where, bench: Bench):
    cli("rig", "new", bench.template, "--out", where, *[a for kv in bench.rig_set for a in ("--set", kv)], check=True)
    return where


def _textbook(bench: Bench, off: bool, **physical) -> Rig:
    return Rig(**{**bench.nominal, **(bench.off if off else {}), **physical})


# (textbook rig's physical cause, the bank's effect for it)
CAUSES = {
    "overlap": ({"overlap": 0.08}, ("deadband", {"width": 0.08 / SPOOL_GAIN_PER_VOLT})),
    "weaker_retract_edges": ({"negative_flow_ratio": 0.7}, ("valve_asymmetry", {"ratio": 0.7})),
    "piston_leak": ({"piston_leakage": 3e-12}, ("leakage", {"internal": 3e-12})),
    "bus_delay": ({"command_delay": 0.08}, ("delay", {"delay": 0.08})),
    # a rod force on the slide; on a boom it would be a torque varying with the arm, not the bank's
    "seal_friction": ({"coulomb": 2000.0}, ("coulomb_friction", {"torque": 2000.0, "smoothing_velocity": 1e-3})),
    # a fixed pump of 0.1 L/s behind the supply's relief: the supply falls while the valve asks for more
    "small_pump": ({"pump_flow": 1e-4}, ("pump_limit", {"max_flow": 1e-4})),
}
REPLAYS = ([("hanging", None), ("vertical", None), ("boom", None)]
           + [("hanging" if k % 2 else "vertical", c) for k, c in enumerate(CAUSES)]
           + [("boom", c) for c in CAUSES if c != "seal_friction"])


@pytest.mark.parametrize("rig,cause", REPLAYS)
def test_the_kernel_moves_the_joint_as_the_textbook_model_does(cli, tmp_path, rig, cause):
    """Same rig, same command (the textbook rig's 20 s closed-loop log, replayed open loop): the
    kernel's position stays within 1 mm RMS of the textbook's over ~50 mm of a slide's motion, and
    within 1 mrad over ~140 mrad of the boom's (achieved 0.06-0.25 mm, 0.13-0.55 mrad: the hose's
    laminar drop, the orifice regularisations and where the overlap sits differ; behind a small pump
    0.12 mm and 0.88 mrad: the textbook's relief holds the supply over its last 2 bar, the spec's pump
    compensator over 5). Each cause is
    large enough to tell: the kernel with its effect at half the magnitude is 1.8 mm (friction,
    delay) to 25 mm (leak) away on the slide, without it 3.6 mm or more."""
    from sim_core.kernel import layout as L
    from sim_core.plant import Plant
    from sim_core.simulator import Simulator

    bench = BENCHES[rig]
    j = bench.joint
    physical, effect = CAUSES[cause] if cause else ({}, None)
    textbook_rig = _textbook(bench, False, sensor_noise=0.0, sensor_bits=24, **physical)
    rows = closed_loop_log(textbook_rig, seed=1, duration=20.0, **bench.loop)
    plant = Plant.from_robot(_rig_dir(cli, tmp_path / "rig", bench))
    spec = plant.spec.copy()
    a, b = spec.get(f"joints.{j}.sensor.A"), spec.get(f"joints.{j}.sensor.B")
    assert (a, b) == (textbook_rig.sensor_a, textbook_rig.sensor_b)
    spec.set(f"joints.{j}.initial_position", rows[0, 1] * a + b)
    spec.set(f"joints.{j}.sensor.noise", 0.0)
    spec.set(f"joints.{j}.sensor.bits", 0.0)
    if effect:
        spec.enable_effect(effect[0], None if EFFECTS[effect[0]].scope == "global" else j, **effect[1])
    sim = Simulator(plant.create_context(spec, seed=0))
    q = [sim.sample()[0][L.YA_SENS_V] * a + b]
    for k in range(len(rows) - 1):
        q.append(sim.step(np.array([rows[k, 2]]), rows[k + 1, 0] - rows[k, 0])[0][L.YA_SENS_V] * a + b)
    textbook = rows[:, 1] * a + b
    assert textbook.std() > bench.moved
    assert np.sqrt(np.mean((np.array(q) - textbook) ** 2)) < bench.tolerance


def _log(tmp_path, bench: Bench, textbook_rig: Rig, seed: int):
    rows = closed_loop_log(textbook_rig, seed=seed, **bench.loop)
    write_headerless(rows, tmp_path / "log.csv")
    j = bench.joint
    return ("--no-header", "--column", "time=0", "--column", f"q_{j}=1:sensor_volts", "--column", f"u_{j}=2")


# (textbook cause, its rig, seed) -> the effect the diagnosis must name and its parameter's truth;
# one case per cause, the boom's beside a second cause or a harder clean record
# (benchmarks/bench_textbook_rig.py draws every cause on every rig)
HIDDEN = {
    "clean": ({}, "hanging", 1, None),
    # the tip load twice the spec's and the supply 13 % low: alone the load would need more than its range
    "clean_boom_heavy": (dict(rated_flow=3.6e-4, supply=1.212e7, load_mass=76.75, viscous=10330.0), "boom", 2, None),
    "overlap": ({"overlap": 0.07}, "vertical", 2, ("deadband", "width", 0.07 / SPOOL_GAIN_PER_VOLT)),
    "weaker_retract_edges": ({"negative_flow_ratio": 0.7}, "hanging", 3, ("valve_asymmetry", "ratio", 0.7)),
    "piston_leak": ({"piston_leakage": 3e-12}, "hanging", 2, ("leakage", "internal", 3e-12)),
    "bus_delay": ({"command_delay": 0.05}, "vertical", 3, ("delay", "delay", 0.05)),
    "null_bias": ({"null_bias": -0.02}, "hanging", 1, ("valve_offset", "offset", -0.02 / SPOOL_GAIN_PER_VOLT)),
    "small_pump": ({"pump_flow": 1.1e-4}, "vertical", 2, ("pump_limit", "max_flow", 1.1e-4)),
    # two causes at once: beside stronger retract edges an overlap alone makes the model worse
    "overlap_and_stronger_edges": ({"overlap": 0.045, "negative_flow_ratio": 1.45}, "vertical", 2,
                                   ("deadband", "width", 0.045 / SPOOL_GAIN_PER_VOLT), ("valve_asymmetry", "ratio", 1.45)),
    "null_bias_and_overlap_boom": ({"null_bias": 0.015, "overlap": 0.06}, "boom", 2,
                                   ("valve_offset", "offset", 0.015 / SPOOL_GAIN_PER_VOLT),
                                   ("deadband", "width", 0.06 / SPOOL_GAIN_PER_VOLT)),
}


@pytest.mark.parametrize("case", list(HIDDEN))
def test_diagnose_says_what_the_textbook_rig_has_that_the_template_has_not(cli, tmp_path, case):
    """The four commands of the README on the textbook rig's log: a clean rig is no discrepancy; a
    hidden cause is named as its effect with the parameter within 10 % (15 % for a leak, whose size
    hangs on the supply the calibration holds, and for two causes at once) of the truth, and nothing
    else is named (benchmarks/bench_textbook_rig.py over 9 draws each: within 5 %, a leak within
    14.4 %; two causes within 12.7 %)."""
    physical, rig_name, seed, *expect = HIDDEN[case]
    bench = BENCHES[rig_name]
    rig = _rig_dir(cli, tmp_path / "rig", bench)
    reading = _log(tmp_path, bench, _textbook(bench, True, **physical), seed)
    cli("import", tmp_path / "log.csv", "--robot", rig, "--out", tmp_path / "rec.csv", *reading, check=True)
    proc = cli("diagnose", "--robot", rig, tmp_path / "rec.csv", "--report", tmp_path / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    if expect == [None]:
        assert d["verdict"] == "no_significant_discrepancy", d["selected"]
        return
    assert d["verdict"] == "discrepancy", d["decision"]
    assert sorted(s["effect"] for s in d["selected"]) == sorted(e for e, _, _ in expect)
    for effect, param, truth in expect:
        named = next(s for s in d["selected"] if s["effect"] == effect)
        assert named["params"][param] == pytest.approx(truth, rel=0.15 if effect == "leakage" or len(expect) > 1 else 0.10)


def test_a_recalibration_the_end_stop_disproves_gives_way_to_one_with_a_parameter_held(cli, tmp_path):
    """The hanging load lifted into its end stop: set-points down to 4 cm beyond the stroke's end, the
    stop first touched in the validation data. Once the overlap is named as a deadband, the
    calibration redone on the estimation data identifies a sensor offset of about 3 cm (it fits
    millimetres of misfit with where the chambers' volumes sit), which puts the model's end stop
    3 cm off: the validation score falls from 94 to 89 (kept as it was, the benchmark's record of this
    kind came out unexplained_discrepancy; not kept at all, this one named an area ratio beside the
    deadband: the load, the supply and the seal friction stay at the spec's). The recalibration is
    redone with each newly identified parameter held in turn, and the best that keeps the score is
    kept: the deadband alone, within 10 %."""
    bench = BENCHES["hanging"]
    rig = _rig_dir(cli, tmp_path / "rig", bench)
    rows = closed_loop_log(_textbook(bench, True, overlap=0.12), seed=1, **{**bench.loop, "references": (-0.04, 0.36)})
    assert rows[:, 1].min() == 0.0                       # the premise: the sensor reads the stop (0 V)
    write_headerless(rows, tmp_path / "log.csv")
    cli("import", tmp_path / "log.csv", "--robot", rig, "--out", tmp_path / "rec.csv", "--no-header", "--column",
        "time=0", "--column", "q_lift=1:sensor_volts", "--column", "u_lift=2", check=True)
    proc = cli("diagnose", "--robot", rig, tmp_path / "rec.csv", "--report", tmp_path / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    redone = d["calibration"]["recalibrations"][0]
    assert redone["freed_validation_score"] < redone["validation_score"][0] - 2.0, redone    # the premise
    assert redone["held"] == "effects.sensor_offset.lift.offset"
    # keeps the score: within the 2-point threshold of the model before it (98.93 -> 98.76 on an AMD EPYC,
    # a little above on another CPU), where freeing the offset lost more
    assert redone["validation_score"][1] >= redone["validation_score"][0] - 2.0
    assert [s["effect"] for s in d["selected"]] == ["deadband"], (d["verdict"], d["selected"])
    assert d["selected"][0]["params"]["width"] == pytest.approx(0.12 / SPOOL_GAIN_PER_VOLT, rel=0.10)


@pytest.mark.parametrize("rig_name,seed", [("hanging", 2), ("vertical", 3)])
def test_a_measured_rigs_seal_friction_is_named_or_listed_as_close(cli, tmp_path, rig_name, seed):
    """Coulomb friction with the supply and the load measured (written in, [estimated] lines deleted):
    with the seal's viscous friction still unknown a position-only log sets the same two speeds per
    volt for a Coulomb friction, a valve asymmetry, an area ratio and a payload. Whichever is named,
    the friction is named or listed among the rivals within the margin, with what would decide, in
    diagnosis.json and on the command line."""
    bench = BENCHES[rig_name]
    rig = _rig_dir(cli, tmp_path / "rig", bench)
    measured(rig, {"supply.pressure": bench.off["supply"], "effects.payload.lift.mass": bench.off["load_mass"]})
    reading = _log(tmp_path, bench, _textbook(bench, True, coulomb=1500.0), seed)
    proc = cli("diagnose", "--robot", rig, tmp_path / "log.csv", *reading, "--report", tmp_path / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    assert d["verdict"] == "discrepancy" and len(d["selected"]) == 1, d["decision"]
    s = d["selected"][0]
    if s["effect"] == "coulomb_friction":
        assert s["params"]["torque"] == pytest.approx(1500.0, rel=0.15)
        return
    assert s["ambiguous"], s
    rival = [r for r in s["rivals"] if r["effect"] == "coulomb_friction"]
    assert rival and rival[0]["decided_by"], s["rivals"]
    line = next(x for x in proc.stdout.splitlines() if x.strip().startswith(s["effect"]))
    assert "coulomb_friction" in line and ("as close: " in line or "ambiguous with coulomb_friction" in line)
