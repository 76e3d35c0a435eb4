"""An estimated parameter the record pushes past an end of its declared range stands in for every
named effect, freed beyond that end: where it explains the record better than the effect, the
effect was standing in for it (a calibration finding); as well, the effect stays named and says the
record does not tell them apart (a lighter load than declared and a valve asymmetry set the same
up/down speeds on a record without pressures)."""

import json

import pytest

from rig_records import closed_loop_record, write_headerless
from sim_core.identification import decision as dc
from sim_core.identification.beyond_range import BeyondRange, stopped_at_an_end, widened
from sim_core.identification.candidates import Candidate
from sim_core.identification.parameters import FreeParameter
from sim_core.model.spec import load_robot

TRUE_LOAD = 10.0          # kg, under the boom template's declared [20, 85]


def test_an_end_moves_out_by_the_ranges_width_inside_the_physical_bounds():
    lin = FreeParameter("p", 20.0, 85.0)
    assert widened(lin, "lower", (-1000.0, 5000.0)).lower == pytest.approx(-45.0)
    assert widened(lin, "lower", (0.0, 5000.0)).lower == 0.0                      # clipped at the bound
    assert widened(lin, "upper", (-1000.0, 5000.0)).upper == pytest.approx(150.0)
    assert widened(lin, "upper", (-1000.0, 85.0)) is None                           # no room left
    w = widened(lin, "lower", (-1000.0, 5000.0))
    assert (w.upper, lin.lower) == (85.0, 20.0)       # the other end and the original stay as they were
    log = FreeParameter("q", 1e6, 1e7, log=True)
    assert widened(log, "upper", (0.0, 1e9)).upper == pytest.approx(1e8)             # by its ratio
    assert widened(log, "lower", (0.0, 1e9)).lower == pytest.approx(1e5)


def test_a_load_may_be_set_down_whatever_its_declared_range():
    cyl = FreeParameter("m", 50.0, 205.0, log=True)       # the cylinder template's 100 kg: [50, 205]
    assert widened(cyl, "lower", (-1000.0, 5000.0)).lower == pytest.approx(50.0 * 50.0 / 205.0)   # by its ratio
    w = widened(cyl, "lower", (-1000.0, 5000.0), absent=0.0)
    assert w.lower == 0.0 and not w.log                   # on to none: a load set down
    assert widened(cyl, "upper", (-1000.0, 5000.0), absent=0.0).upper == pytest.approx(205.0 * 205.0 / 50.0)
    lin = FreeParameter("p", 20.0, 85.0)
    assert widened(lin, "lower", (-1000.0, 5000.0), absent=0.0).lower == pytest.approx(-45.0)  # already past it
    # the effect owns it: the payload's mass may be absent, a supply may not
    spec = load_robot("hydrolek")
    free = [FreeParameter("effects.payload.j2.mass", 50.0, 205.0, log=True),
            FreeParameter("supply.pressure", 9.8e6, 16.1e6, log=True)]
    rows = [{"parameter": fp.key, "fitted": fp.lower, "identified": False} for fp in free]
    load, supply = stopped_at_an_end(spec, rows, free, {fp.key for fp in free})
    assert load.lower == 0.0
    assert supply.lower == pytest.approx(9.8e6 * 9.8e6 / 16.1e6)


def test_only_estimated_parameters_stopped_at_an_end_stand_in_the_load_first():
    spec = load_robot("hydrolek")
    free = [FreeParameter("supply.pressure", 9.8e6, 16.1e6), FreeParameter("effects.payload.j2.mass", 20.0, 85.0),
            FreeParameter("joints.j2.valve.rated_flow", 1e-5, 1e-4, log=True),
            FreeParameter("effects.sensor_offset.j2.offset", -0.1, 0.1)]
    rows = [{"parameter": "supply.pressure", "fitted": 16.1e6, "identified": False},
            {"parameter": "effects.payload.j2.mass", "fitted": 20.0, "identified": False},
            {"parameter": "joints.j2.valve.rated_flow", "fitted": 1e-4, "identified": False},      # not estimated
            {"parameter": "effects.sensor_offset.j2.offset", "fitted": 0.05, "identified": False}]  # inside
    nuisance = {"supply.pressure", "effects.payload.j2.mass", "effects.sensor_offset.j2.offset"}
    got = stopped_at_an_end(spec, rows, free, nuisance)
    assert [fp.key for fp in got] == ["effects.payload.j2.mass", "supply.pressure"]
    assert got[0].lower < 20.0 and got[0].upper == 85.0
    assert got[1].upper > 16.1e6 and got[1].lower == 9.8e6
    # identified at an end: not a stand-in (identifiability says so only for values inside)
    rows[0]["identified"] = True
    assert [fp.key for fp in stopped_at_an_end(spec, rows, free, nuisance)] == ["effects.payload.j2.mass"]


def _named(effect="valve_asymmetry"):
    c = Candidate(effect, "boom", [FreeParameter(f"effects.{effect}.boom.ratio", 0.2, 5.0, log=True, null=1.0)])
    return dc.Evaluation(c, {}, {}, {}, 1.0, {}, gain=20.0)


def _stand_in(score, value, bound=None, p=None):
    """A valve asymmetry named in a model scoring 97.0; ``p`` (default: the load freed beyond its
    declared [20, 85]) refitted in its place scores ``score`` at ``value``."""
    p = p or BeyondRange("effects.payload.boom.mass", -45.0, 85.0, declared=(20.0, 85.0))
    ev = _named()

    def refit_instead(model, e, rest, q):
        return "model with " + q.key, score, value, bound

    out = dc.stand_in([ev], "model", 97.0, stand_ins=lambda e: [p], refit_instead=refit_instead)
    return out, ev


def test_beyond_its_range_a_parameter_replaces_an_effect_only_where_it_explains_the_record_better():
    (model, kept, found), ev = _stand_in(99.5, 12.0)                    # 2.5 points better: the finding
    assert kept == [] and model == "model with effects.payload.boom.mass" and found[0][2] == 12.0
    for score in (97.02, 95.5, 98.9):                                    # as well (within 2 points): stays, says so
        (model, kept, found), ev = _stand_in(score, 12.0)
        assert kept == [ev] and found == [] and model == "model"
        assert [r["parameter"] for r in ev.as_well_beyond_range] == ["effects.payload.boom.mass"]
        assert ev.as_well_beyond_range[0]["declared_range"] == [20.0, 85.0]
    (model, kept, found), ev = _stand_in(94.9, 12.0)                     # worse by the threshold: stays, silent
    assert kept == [ev] and ev.as_well_beyond_range == []
    # ended inside its declared range or on its widened bound: what explained the record was not the range
    for value, bound in ((25.0, None), (-45.0, "lower")):
        (model, kept, found), ev = _stand_in(99.5, value, bound)
        assert kept == [ev] and found == [] and ev.as_well_beyond_range == []
    # a plain stand-in (a held nominal parameter, no declared range) replaces within the threshold, as before
    (model, kept, found), ev = _stand_in(96.0, 1.1, p=FreeParameter("links.mass_scale", 0.5, 2.0))
    assert kept == [] and ev.as_well_beyond_range == []


def test_a_load_under_its_declared_range_is_said_to_explain_the_record_as_well(cli, tmp_path):
    rig = tmp_path / "rig"
    cli("rig", "new", "boom", "--out", rig, check=True)
    spec = load_robot(rig)
    j = spec.joint_names[0]
    key = f"effects.payload.{j}.mass"
    i = spec.tree.index(spec.joint(j).dof)
    span = float(spec.tree.upper[i] - spec.tree.lower[i])
    off = {f"joints.{j}.valve.rated_flow": 1.1, "supply.pressure": 0.9}
    rows, _ = closed_loop_record(rig, hidden=("payload", {"mass": TRUE_LOAD}), off=off, seed=1, duration=60.0,
                                 start_offset=0.05 * span)
    write_headerless(rows, tmp_path / "log.csv")
    cli("import", tmp_path / "log.csv", "--robot", rig, "--out", tmp_path / "rec.csv", "--no-header",
        "--column", "time=0", "--column", f"q_{j}=1:sensor_volts", "--column", f"u_{j}=2", check=True)
    proc = cli("diagnose", "--robot", rig, tmp_path / "rec.csv", "--report", tmp_path / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "rep" / "diagnosis.json").read_text())
    row = {r["parameter"]: r for r in d["calibration"]["changes"]}[key]
    lower = float(row["why"].split("range [")[1].split(",")[0])
    # the premise: the calibration stops the load at its declared lower end, and an effect that makes up
    # part of the load's pull is named
    assert lower == 20.0 and TRUE_LOAD < lower
    assert "lower end of its range" in row["not_identified_because"]
    assert d["selected"], d["verdict"]
    # every named effect says the load beyond its range explains the record as well (the load first), at a
    # value under the range near the truth (conditional on the supply held at nominal, 10 % over the
    # truth's: a lighter load and a weaker supply set the same speeds), and what would decide
    for s in d["selected"]:
        first = s["as_well_beyond_range"][0]
        assert first["parameter"] == key and first["declared_range"] == [20.0, 85.0]
        assert first["value"] < lower and first["value"] == pytest.approx(TRUE_LOAD, rel=0.6)
        assert abs(first["score"] - first["score_with_effect"]) < d["decision"]["threshold_points"]
        assert "measuring " + key in first["decided_by"]
    assert "as well explained by " + key in proc.stdout


def test_a_fleet_row_and_its_summary_say_it_too():
    """The fleet's row of a record, its line in the log and its summary page carry the parameter."""
    from sim_core.fleet.index_html import index_html
    from sim_core.fleet.rows import record_row
    from sim_core.fleet.runner import _finish_text

    item = {"effect": "valve_asymmetry", "joint": "boom", "params": {"ratio": 0.99}, "ci95": {"ratio": [0.98, 1.0]},
            "gain": 23.7, "ambiguous": False,
            "as_well_beyond_range": [{"parameter": "effects.payload.boom.mass", "value": 14.2, "declared_range": [20.0, 85.0],
                                      "score": 97.61, "score_with_effect": 97.59, "decided_by": "measuring it"}]}
    diag = {"verdict": "discrepancy", "selected": [item], "baseline": {"fit": {"boom": 36.8}},
            "extended": {"fit": {"boom": 99.4}}, "candidates": [], "data": {"targets": ["boom"]}}
    row = record_row("log", "log.csv", None, "diagnosed", diag, seconds=7.0)
    assert row["effects"][0]["as_well_beyond_range"] == ["effects.payload.boom.mass"]
    assert "as well: effects.payload.boom.mass beyond its declared range" in _finish_text(row)
    page = index_html({"records": [row], "robot": "rig", "generated": "now", "backend": None, "effects": [],
                       "totals": {"records": 1, "diagnosed": 1, "unchanged": 0, "failed": 0,
                                  "verdicts": {"discrepancy": 1}}})
    assert "as well: effects.payload.boom.mass beyond its declared range" in page
    # and nothing where the diagnosis says nothing of the kind
    del item["as_well_beyond_range"]
    plain = record_row("log", "log.csv", None, "diagnosed", diag, seconds=7.0)
    assert plain["effects"][0]["as_well_beyond_range"] == [] and "as well" not in _finish_text(plain)
