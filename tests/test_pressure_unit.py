"""A chamber pressure logged in another unit than it is read in (ingest/pressure_band.py): the band a
circuit allows and the readings that fit it, on synthetic figures; then the user's way: HydroLek's
record with its pressures logged in bar and read as Pa -> ``import`` notes the unit that fits ->
``diagnose`` names it first in the record's causes.

Expected values come from the traces and logs written here (the unit put in), not from the code under test."""

import csv
import json

import numpy as np
import pytest

from conftest import run_cli

from sim_core.ingest.pressure_band import (OUTSIDE_SHARE, RELIEF_FACTOR, SMALL_SHARE, alternatives, band, causes,
                                           implausible, plausible_readings)
from sim_core.ingest.units import UNITS, parse_unit
from sim_core.model.spec import load_robot

SPEC = load_robot("hydrolek")
SUPPLY = SPEC.get("supply.pressure")
READINGS = {n: parse_unit(n, "pressure", column="p") for n in UNITS["pressure"]}


def chamber(n=500):
    """A chamber's pressure on a 14 MPa circuit (Pa): a load held at 4-9 MPa, dips towards tank."""
    t = np.linspace(0.0, 10.0, n)
    return 6.5e6 + 2.5e6 * np.sin(1.3 * t) - 1.5e6 * (np.sin(0.4 * t) > 0.9)


def test_a_chamber_within_the_circuit_is_plausible_and_off_by_a_unit_is_not():
    p = chamber()
    assert implausible(p, SPEC, []) is None
    assert "the largest is" in implausible(p / 1e5, SPEC, ["bar"])          # bar read as Pa
    assert "outside" in implausible(p * 1e5, SPEC, [])                      # Pa read as bar
    lo, hi = band(SPEC)
    assert lo < SPEC.get("fluid.cavitation_pressure") and hi == pytest.approx(RELIEF_FACTOR * SPEC.get("supply.relief_pressure"))
    just = np.full(100, 1.1 * SMALL_SHARE * SUPPLY)
    assert implausible(just, SPEC, ["kPa"]) is None and implausible(just / 1.2, SPEC, ["kPa"]) is not None
    assert implausible(just / 1.2, SPEC, []) is None             # small, but no unit fits: a chamber at tank
    assert alternatives(np.full(50, 2e5), SPEC, "Pa") == []       # ... as a return side at 2 bar is
    assert alternatives(np.zeros(50), SPEC, "Pa") == []           # ... or an unconnected transducer
    over = np.where(np.arange(100) < 100 * (OUTSIDE_SHARE - 0.1), 2 * hi, 5e6)
    assert implausible(over, SPEC, []) is None                              # a minority of spikes is no unit


@pytest.mark.parametrize("unit", ["kPa", "bar", "MPa", "psi"])
def test_the_one_reading_that_fits_is_the_unit_the_pressure_was_logged_in(unit):
    raw = chamber() / READINGS[unit].scale
    assert plausible_readings(raw, READINGS, SPEC) == [unit]


def test_the_cause_groups_the_columns_and_gives_the_factor():
    p = chamber() / 1e5
    found = {c: (implausible(p, SPEC, ["bar"]), p) for c in ("p_j2_a", "p_j2_b")}
    (said,) = causes(found, SPEC)
    assert said.startswith("p_j2_a, p_j2_b: the largest is") and "x 100000 (bar read as Pa)" in said
    assert "`--column COLUMN=SOURCE:bar`" in said


# ---- the user's way --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def bar_log(tmp_path_factory):
    """HydroLek's j2 moved by a multisine for 20 s, simulated, its pressures written in bar under the
    dataset's own header (which reads them as Pa)."""
    root = tmp_path_factory.mktemp("bar")
    t = np.arange(0.0, 20.0, 0.005)
    u = 2.0 * np.sin(2 * np.pi * 0.2 * t) + 1.5 * np.sin(2 * np.pi * 0.5 * t + 1.0) + np.sin(2 * np.pi * 1.1 * t + 2.0)
    cols = {"time": t, **{f"u_{j}": (u if j == "j2" else 0.0 * t) for j in SPEC.joint_names}}
    with open(root / "in.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(list(cols))
        w.writerows(zip(*cols.values()))
    run_cli("simulate", "--robot", "hydrolek", "--input", root / "in.csv", "--out", root / "sim.csv", "--seed", "1",
               check=True)
    rows = list(csv.reader(open(root / "sim.csv")))
    pcols = [i for i, c in enumerate(rows[0]) if c.startswith("p_")]
    with open(root / "log.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(rows[0])
        for r in rows[1:]:
            w.writerow([f"{float(v) / 1e5:.6g}" if i in pcols else v for i, v in enumerate(r)])
    return root


def test_import_notes_the_unit_the_pressures_fit(cli, bar_log):
    proc = cli("import", "--robot", "hydrolek", bar_log / "log.csv", "--out", bar_log / "as_pa.csv")
    assert proc.returncode == 0, proc.stderr
    assert "p_j2_a: the largest is" in proc.stdout and "(`--column p_j2_a=p_j2_a:bar`) it fits" in proc.stdout
    proc = cli("import", "--robot", "hydrolek", bar_log / "sim.csv", "--out", bar_log / "right.csv")
    assert proc.returncode == 0 and "no chamber" not in proc.stdout


def test_diagnose_names_the_pressure_unit_first(cli, bar_log):
    proc = cli("diagnose", "--robot", "hydrolek", bar_log / "log.csv", "--report", bar_log / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    d = json.loads((bar_log / "rep" / "diagnosis.json").read_text())
    assert d["verdict"] == "unexplained_discrepancy"
    assert "p_j2_a" in d["data"]["implausible_pressures"]
    first = d["unexplained"]["record_causes"][0]
    assert "p_j2_a" in first and "(bar read as Pa)" in first
    assert "SOURCE:bar`" in proc.stdout
