"""What a record can show (detectability.py): the ladder of magnitudes, the first-order refit of the
calibration, and, end to end, that an effect the report says the record shows from a magnitude is
named well above it and not named well below it."""

import json
import math

import numpy as np
import pytest

from sim_core.identification import detectability
from sim_core.identification.candidates import bank
from sim_core.identification.output_error import Problem
from sim_core.identification.parameters import FreeParameter
from sim_core.identification.record import Record
from sim_core.identification.simulation import Outputs
from sim_core.model.spec import load_robot

from conftest import run_cli
from diagnose_cases import CLEAN, generate


def test_a_linear_ladder_runs_from_the_null_to_the_far_bound_a_factor_2_apart():
    fp = FreeParameter("effects.valve_offset.j2.offset", -1.5, 1.5, null=0.0)
    v = detectability.rungs(fp)
    assert v[-1] == pytest.approx(1.5)                  # both bounds as far: the upper one
    assert np.allclose(np.diff(np.log(v)), math.log(2.0))
    assert v[0] == pytest.approx(1.5 / 2 ** 7)


def test_a_ladder_turns_to_the_bound_farther_from_the_null():
    fp = FreeParameter("effects.valve_asymmetry.j2.ratio", 0.3, 1.2, null=1.0)
    v = detectability.rungs(fp)
    assert v[-1] == pytest.approx(0.3) and all(0.3 <= x < 1.0 for x in v)
    assert v == sorted(v, reverse=True)                 # nearest the null first


def test_a_named_value_turns_the_ladder_to_its_own_side_of_the_null():
    """A spec's 1.2 V deadband (the harvester's valves) in a search range of 0-4.5 V: a deadband named
    at 0.8 V is narrower than the spec's, so what the record shows of it is found from 1.2 V down;
    the ladder up to 4.5 V said "from about 1.6 V" beside it. A value on the far side, or none, keeps
    the ladder to the farther bound; so does a value at the null."""
    fp = FreeParameter("effects.deadband.swing.width", 0.0, 4.5, null=1.2)
    down = detectability.rungs(fp, toward=0.8)
    assert down[-1] == pytest.approx(0.0) and down == sorted(down, reverse=True) and down[0] < 1.2
    assert down[0] == pytest.approx(1.2 - 1.2 / 2 ** 7)
    assert detectability.rungs(fp, toward=2.0) == detectability.rungs(fp) == detectability.rungs(fp, toward=1.2)
    assert detectability.rungs(fp)[-1] == pytest.approx(4.5)
    offset = FreeParameter("effects.valve_offset.j2.offset", -1.5, 1.5, null=0.0)
    assert detectability.rungs(offset, toward=-0.3)[-1] == pytest.approx(-1.5)
    leak = FreeParameter("effects.leakage.j2.internal", 1e-15, 3e-10, log=True, null=2e-12)
    assert detectability.rungs(leak, toward=5e-13)[-1] == pytest.approx(1e-15)
    assert detectability.rungs(leak, toward=5e-11)[-1] == pytest.approx(3e-10)


def test_a_log_ladder_takes_sixteenths_of_the_range():
    fp = FreeParameter("effects.coulomb_friction.j2.torque", 0.1, 1e4, log=True, null=0.0)
    v = detectability.rungs(fp)
    assert len(v) == 16 and v[-1] == pytest.approx(1e4)
    assert np.allclose(np.diff(np.log(v)), math.log(1e5) / 16)
    # a flow limit vanishes at infinity: the ladder comes down from the upper bound
    fs = FreeParameter("effects.flow_saturation.j2.max_flow", 1e-6, 1e-3, log=True, null=math.inf)
    assert detectability.rungs(fs)[-1] == pytest.approx(1e-6)
    assert detectability.rungs(FreeParameter("x", 0.0, 1.0, null=None)) == []
    # no null (line dynamics): over the whole range, from the other bound to the one given
    ld = FreeParameter("effects.line_dynamics.j2.bulk_modulus_scale", 0.05, 3.0, log=True, null=math.nan)
    down = detectability.one_way(ld, 0.05)
    assert len(down) == 16 and down[-1] == pytest.approx(0.05) and down == sorted(down, reverse=True)
    assert down[0] == pytest.approx(3.0 * (0.05 / 3.0) ** (1 / 16))
    up = detectability.one_way(ld, 3.0)
    assert up[-1] == pytest.approx(3.0) and up == sorted(up)


def _problem(angle, t):
    rec = Record("synthetic", t, np.zeros((t.size, 1)), {"j": angle}, {}, ["j"], ["j"], {"j": float(angle[0])})
    return Problem(rec, ["j"])


def test_the_first_order_refit_takes_up_what_the_calibration_can_and_nothing_else():
    t = np.arange(0.0, 10.0, 0.01)
    base = np.sin(t)
    prob = _problem(base, t)
    out = lambda a: Outputs({"j": a}, {})
    # the one calibrated parameter scales the motion: its Jacobian column, d residual / dx = -d sim / dx
    col = -np.concatenate([v / prob.scale[("j", ch)] for ch, v in
                           (("angle", base), ("velocity", prob.simulated(out(base))[("j", "velocity")]))])
    J = col[:, None]
    scaled = out(1.3 * base)
    took = detectability.absorbed(prob, out(base), scaled, J)
    assert np.max(np.abs(took.angles["j"] - 1.3 * base)) < 1e-9          # in the span: all of it
    bent = out(base + 0.1 * np.cos(3 * t))
    left = detectability.absorbed(prob, out(base), bent, J)
    assert np.max(np.abs(left.angles["j"] - base)) < 0.02                 # orthogonal to it: almost none
    none = detectability.absorbed(prob, out(base), scaled, None)
    assert np.array_equal(none.angles["j"], base)                        # nothing calibrated: nothing taken
    # the expected gain: none for what the calibration takes up, points for what it cannot
    g_scaled = detectability.expected_gain(prob, out(base), scaled, J, ["j"], {"j": 1e-3}, {}, 0)
    g_bent = detectability.expected_gain(prob, out(base), bent, J, ["j"], {"j": 1e-3}, {}, 0)
    assert abs(g_scaled) < 0.2 and g_bent > 5.0


@pytest.fixture(scope="module")
def clean_record(tmp_path_factory):
    where = tmp_path_factory.mktemp("clean")
    case = CLEAN[0]
    meas, _ = generate(run_cli, case, where)
    proc = run_cli("diagnose", "--robot", case.robot, meas, "--report", where / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    return case, json.loads((where / "rep" / "diagnosis.json").read_text()), proc.stdout


def test_every_effect_not_named_has_what_the_record_shows(clean_record):
    case, d, stdout = clean_record
    assert d["verdict"] == "no_significant_discrepancy"
    rows = d["detectable"]["effects"]
    # every candidate: one whose effect vanishes at some value of its parameter from there, one with
    # no such value (line dynamics replaces the hoses' lumping at any stiffness) from the end of its
    # range where it shows less
    assert {(r["effect"], r["joint"]) for r in rows} == {(c["effect"], c["joint"]) for c in d["candidates"]}
    no_null = [r for r in rows if "from_weaker_end" in r]
    assert [r["effect"] for r in no_null] == ["line_dynamics"]
    for r in no_null:
        assert r["null"] is None
        assert sorted([r["from_weaker_end"], r["range_end"]]) == pytest.approx([0.05, 3.0])
    for r in rows:
        gains = [x["expected_gain"] for x in r["tested"]]
        if r["shows_from"] is None:
            assert gains[-1] is None or gains[-1] < d["detectable"]["threshold_points"]
        else:
            hit = next(x for x in r["tested"] if x["value"] == r["shows_from"])
            assert hit["expected_gain"] >= d["detectable"]["threshold_points"]
    assert "would show (estimated):" in stdout


@pytest.mark.parametrize("factor, named", [(4.0, True), (0.25, False)], ids=["4x_named", "quarter_not_named"])
def test_a_valve_offset_is_named_above_what_the_record_shows_and_not_below(cli, clean_record, tmp_path, factor, named):
    case, d, _ = clean_record
    row = next(r for r in d["detectable"]["effects"] if r["effect"] == "valve_offset")
    assert row["shows_from"] is not None
    offset = factor * row["shows_from"]
    meas, _ = generate(cli, case, tmp_path, extra=[("valve_offset", case.joint, {"offset": offset})])
    proc = cli("diagnose", "--robot", case.robot, meas, "--report", tmp_path / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    got = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    names = [s["effect"] for s in got["selected"]]
    assert (names == ["valve_offset"]) if named else (names == []), (offset, names, got["verdict"])
    if named:
        # the named effect's own row, on the model without it: the same record shows it from about
        # where the clean record's report said (the same motion, the effect's trace aside)
        own = next(r for r in got["detectable"]["effects"] if r["effect"] == "valve_offset")
        assert own["named"] and own["shows_from"] is not None
        assert 0.25 * row["shows_from"] <= own["shows_from"] <= 4.0 * row["shows_from"]
        assert not any(r["named"] for r in got["detectable"]["effects"] if r["effect"] != "valve_offset")


def named_alone(cli, tmp_path, robot, hidden):
    """``in.csv`` simulated with the ``hidden`` (effect, joint, parameter, value) and diagnosed with the
    deadband and the valve asymmetry: the CLI's answer, diagnosis.json, and the named effect's
    ``detectable`` row, once the effect is asserted named alone within 5 %."""
    effect, joint, name, value = hidden
    cli("simulate", "--robot", robot, "--input", tmp_path / "in.csv", "--out", tmp_path / "m.csv",
        "--effect", f"{effect}:joint={joint},{name}={value}", "--noise-angle", 3e-4, "--seed", 5, check=True)
    proc = cli("diagnose", "--robot", robot, tmp_path / "m.csv", "--report", tmp_path / "rep",
               "--effects", "deadband", "valve_asymmetry", "--quiet")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    assert [(s["effect"], s["joint"]) for s in d["selected"]] == [(effect, joint)]
    assert d["selected"][0]["params"][name] == pytest.approx(value, rel=0.05)
    return proc, d, next(r for r in d["detectable"]["effects"] if r["named"])


def test_a_deadband_named_narrower_than_the_specs_is_searched_below_it(cli, tmp_path):
    """The harvester's valves carry a 1.2 V deadband in the spec; a swing valve with 0.5 V is named
    narrower, and what the record shows of it is searched from 1.2 V down to 0, not up to 4.5 V
    (which said "from about 1.6 V" beside a named 0.5 V)."""
    cli("excite", "--robot", "harvester", "--joint", "swing", "--duration", 20, "--rate", 100, "--seed", 3,
        "--out", tmp_path / "in.csv", check=True)
    proc, d, row = named_alone(cli, tmp_path, "harvester", ("deadband", "swing", "width", 0.5))
    assert row["null"] == pytest.approx(1.2) and row["range_end"] == pytest.approx(0.0)
    assert row["tested"] and all(t["value"] < 1.2 for t in row["tested"])
    if row["shows_from"] is not None:
        assert "none at width = 1.2 V" in proc.stdout


def test_a_ladder_that_shows_nothing_on_the_short_window_is_searched_on_the_whole_one(cli, tmp_path):
    """The shoulder only rises (1.5 V pushes and rests) for the first 9 s of a 30 s record, then
    steps both ways: a valve asymmetry acts on one direction of the flow, so on the first half of the
    estimation window (0-9 s) no ratio shows, and a 0.6 valve asymmetry named with 140 points read
    "does not reach it within its range". On the whole estimation window it shows."""
    t = np.arange(3000) / 100.0
    u = np.zeros_like(t)
    rise = (t >= 1.0) & (t < 9.0)
    u[rise] = np.where(((t[rise] - 1.0) % 1.0) < 0.5, 1.5, 0.0)
    steps = t >= 9.0
    u[steps] = np.repeat(np.random.default_rng(4).choice([-3.0, 3.0], size=steps.sum() // 40 + 1), 40)[: steps.sum()]
    from sim_core.dataset import write_csv
    write_csv(tmp_path / "in.csv", {"time": t, "u_j2": u})
    proc, d, row = named_alone(cli, tmp_path, "hydrolek", ("valve_asymmetry", "j2", "ratio", 0.6))
    assert row["window"] == "the estimation window"
    assert row["shows_from"] is not None and 0.6 < row["shows_from"] < 1.0
    # a ladder that shows on the short window stays there
    other = next(r for r in d["detectable"]["effects"] if r["effect"] == "deadband")
    assert other["window"] == "the first half of the estimation window" and other["shows_from"] is not None
