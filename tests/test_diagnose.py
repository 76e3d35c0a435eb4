"""hydrohil diagnose finds a hidden effect in 'measured' data, names its joint, recovers its parameter
and gains at least the documented threshold; on clean data it says so; the contract files are right.

Every record is made with ``hydrohil excite`` and ``hydrohil simulate`` from a truth model (see
diagnose_cases.py); ``diagnose`` sees only the CSV.
"""

import json

import pytest

from sim_core.dataset import read_csv
from sim_core.effects import EFFECTS, diagnosable
from sim_core.identification.metrics import nrmse_fit
from sim_core.identification.selection import THRESHOLD_POINTS

from diagnose_cases import CASES, CLEAN, TWO, elbow_hysteresis_record, generate

CONTRACT_TOP = {"robot", "verdict", "baseline", "extended", "selected", "candidates"}


def test_every_effect_is_hidden_in_some_case():
    assert {name for c in CASES for name, _, _ in c.hidden} == set(diagnosable())
    assert {c.robot for c in CASES} == {"hydrolek", "harvester"}


_DIAGNOSED: dict[str, tuple] = {}     # case name -> (measured csv, truth, diagnosis, its directory)


def run_case(cli, case, tmp_path, artifacts=None):
    meas, truth = generate(cli, case, tmp_path)
    proc = cli("diagnose", "--robot", case.robot, meas, "--report", tmp_path / "rep", "--quiet", *case.options)
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    if artifacts is not None:   # the confusion matrix of the README is compiled from these lines
        with open(artifacts / "diagnose_cases.jsonl", "a") as fh:
            fh.write(json.dumps({"case": case.name, "robot": case.robot, "truth": truth, "verdict": d["verdict"],
                                 "selected": [{k: s[k] for k in ("effect", "joint", "params", "gain")} for s in d["selected"]],
                                 "runner_up": d["selected"][0].get("runner_up") if d["selected"] else None,
                                 "best_rejected_gain": max([c["gain"] for c in d["candidates"] if not c["accepted"]], default=None),
                                 "seconds": d["timings_s"]["total"]}) + "\n")
    _DIAGNOSED[case.name] = (meas, truth, d, tmp_path)
    return meas, truth, d


def diagnosed(cli, case, tmp_path):
    """``run_case``'s result for ``case``, reused when an earlier test of this session diagnosed the same
    record (the records are deterministic); returns (measured csv, truth, diagnosis, its directory)."""
    if case.name not in _DIAGNOSED:
        run_case(cli, case, tmp_path)
    return _DIAGNOSED[case.name]


def check_contract(d, robot, sensed):
    assert CONTRACT_TOP <= set(d)
    assert d["robot"] == robot
    assert d["verdict"] in ("discrepancy", "no_significant_discrepancy")
    assert set(d["baseline"]["fit"]) == set(sensed) == set(d["extended"]["fit"])
    for s in d["selected"]:
        assert {"effect", "joint", "params", "ci95", "gain"} <= set(s)
        assert s["effect"] in EFFECTS
        assert set(s["ci95"]) == set(s["params"])
        for k, (lo, hi) in s["ci95"].items():
            assert lo <= s["params"][k] <= hi
    for c in d["candidates"]:
        assert {"effect", "joint", "gain", "bic_delta", "params"} <= set(c)
        assert c["effect"] in EFFECTS


def sensed_columns(csv):
    return [c[2:] for c in read_csv(csv).columns if c.startswith("q_")]


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_hidden_effect_is_found(cli, case, tmp_path, artifacts):
    meas, truth, d = run_case(cli, case, tmp_path, artifacts)
    check_contract(d, case.robot, sensed_columns(meas))
    (name, joint, vals), = truth
    assert d["verdict"] == "discrepancy"
    top = d["selected"][0]
    assert (top["effect"], top["joint"]) == (name, joint), d["selected"]
    for p in case.hidden[0][2]:
        assert top["params"][p] == pytest.approx(vals[p], rel=0.10, abs=0), (p, top["params"], vals)
    assert top["gain"] >= THRESHOLD_POINTS
    # the fit of the diagnosed joint improves on the validation data
    assert d["extended"]["fit"][case.joint] > d["baseline"]["fit"][case.joint]


@pytest.mark.parametrize("case", CLEAN, ids=[c.name for c in CLEAN])
def test_clean_data_has_no_significant_discrepancy(cli, case, tmp_path, artifacts):
    meas, _, d = run_case(cli, case, tmp_path, artifacts)
    check_contract(d, case.robot, sensed_columns(meas))
    assert d["verdict"] == "no_significant_discrepancy"
    assert d["selected"] == []
    assert d["candidates"], "every candidate is still fitted and reported"
    assert max(c["gain"] for c in d["candidates"]) < THRESHOLD_POINTS


@pytest.mark.parametrize("case", TWO, ids=[c.name for c in TWO])
def test_two_hidden_effects_are_both_named(cli, case, tmp_path, artifacts):
    meas, truth, d = run_case(cli, case, tmp_path, artifacts)
    check_contract(d, case.robot, sensed_columns(meas))
    named = {(s["effect"], s["joint"]): s for s in d["selected"]}
    for name, joint, vals in truth:
        assert (name, joint) in named, d["selected"]
        for p, v in vals.items():
            if p in named[(name, joint)]["params"]:
                assert named[(name, joint)]["params"][p] == pytest.approx(v, rel=0.10, abs=0)
    assert len(d["selected"]) == len(truth)


def test_extended_model_runs_in_simulate_and_reproduces_the_record(cli, tmp_path):
    """extended.toml is a --params file: simulating the record's input with it matches the record
    better than the nominal model does."""
    case = next(c for c in CASES if c.name == "deadband")
    meas, truth, d, where = diagnosed(cli, case, tmp_path)
    rep = where / "rep"
    assert (rep / "report.html").stat().st_size > 10_000
    html = (rep / "report.html").read_text()
    assert "deadband" in html and "data:image/png;base64," in html
    for which, extra in (("nominal", []), ("extended", ["--params", rep / "extended.toml"])):
        cli("simulate", "--robot", case.robot, "--input", where / "in.csv", "--out", tmp_path / f"{which}.csv",
            *extra, check=True)
    y = read_csv(meas)[f"q_{case.joint}"]
    fits = {w: nrmse_fit(y, read_csv(tmp_path / f"{w}.csv")[f"q_{case.joint}"]) for w in ("nominal", "extended")}
    assert fits["extended"] > fits["nominal"] + 5.0
    assert fits["extended"] > 95.0


def test_separate_validation_record(cli, tmp_path):
    """--validation: fits are scored on the other record (its whole length)."""
    case = next(c for c in CASES if c.name == "delay")
    meas, truth = generate(cli, case, tmp_path)
    other = tmp_path / "other"
    other.mkdir()
    cli("excite", "--robot", case.robot, "--joint", case.joint, "--duration", 20, "--seed", 99, "--out", other / "in.csv",
        check=True)
    (name, joint, vals), = truth
    cli("simulate", "--robot", case.robot, "--input", other / "in.csv", "--out", other / "val.csv",
        "--effect", f"delay:joint={joint},delay={vals['delay']!r}", "--noise-angle", 3e-4, "--seed", 5, check=True)
    proc = cli("diagnose", "--robot", case.robot, meas, "--validation", other / "val.csv", "--report", tmp_path / "rep",
               "--quiet")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    assert d["validation"]["source"].endswith("val.csv") and d["validation"]["first_sample"] == 0
    assert d["validation"]["samples"] == len(read_csv(other / "val.csv"))
    assert d["validation"]["angle_restart_s"] is None        # open loop: scored over the whole replay
    assert (d["selected"][0]["effect"], d["selected"][0]["joint"]) == ("delay", joint)
    assert d["selected"][0]["params"]["delay"] == pytest.approx(vals["delay"], rel=0.10)


def test_two_joints_excited_together_only_the_hidden_effect_is_named(cli, tmp_path):
    """A record where two joints move at once (each its own PRBS), the elbow often at its end stop,
    a hysteresis hidden on the elbow: it is named there, with its width, and nothing else is (a
    greedy extra pick whose gain came from refitting the others is dropped by the final check)."""
    measured = elbow_hysteresis_record(cli, tmp_path, 60)
    proc = cli("diagnose", "--robot", "hydrolek", measured, "--report", tmp_path / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    check_contract(d, "hydrolek", sensed_columns(measured))
    assert [(s["effect"], s["joint"]) for s in d["selected"]] == [("hysteresis", "j3")], d["selected"]
    assert d["selected"][0]["params"]["width"] == pytest.approx(0.6, rel=0.10)

