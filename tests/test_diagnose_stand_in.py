"""End to end: links heavier than the URDF says are a calibration finding, not a payload.

On a one-joint record a mass error spread over the links loads the joint as a point mass at its
payload point does; the search names ``payload``, and the stand-in pass then frees the links' mass
scale in its place (held during the search: it could absorb a payload, a Coulomb friction, ...). The
scale explains the record as well and moves 3 sigma: a calibration finding. A payload heavier than
any plausible mass error (the scale stops at its bound) stays named, on the same input.
"""

import json

import pytest

EFFECTS = ["payload", "deadband"]
SEED = 7


def _record(cli, where, *extra):
    inp, meas = where / "in.csv", where / "measured.csv"
    cli("excite", "--robot", "hydrolek", "--joint", "j2", "--duration", 30, "--seed", SEED, "--out", inp, check=True)
    cli("simulate", "--robot", "hydrolek", "--input", inp, "--out", meas, "--noise-angle", 4e-4, "--seed", SEED,
        *extra, check=True)
    return meas


def _diagnose(cli, meas, out):
    proc = cli("diagnose", "--robot", "hydrolek", meas, "--report", out, "--effects", *EFFECTS, "--quiet")
    assert proc.returncode == 0, proc.stderr
    return json.loads((out / "diagnosis.json").read_text())


def test_links_fifteen_percent_heavier_are_a_calibration_finding(cli, tmp_path):
    d = _diagnose(cli, _record(cli, tmp_path, "--set", "links.mass_scale=1.15"), tmp_path / "rep")
    assert d["verdict"] == "no_significant_discrepancy", d["selected"]
    (si,) = d["calibration"]["stand_ins"]
    assert si["parameter"] == "links.mass_scale" and si["in_place_of"]["effect"] == "payload"
    assert si["value"] == pytest.approx(1.15, rel=0.03)
    row = next(c for c in d["calibration"]["changes"] if c["parameter"] == "links.mass_scale")
    assert row["identified"] and row["value"] == pytest.approx(1.15, rel=0.03) and "in place of payload" in row["why"]
    payload = [c for c in d["candidates"] if c["effect"] == "payload" and c["joint"] == "j2"]
    assert any("not named" in r for c in payload for r in c["rejected_because"])
    assert "links.mass_scale calibrated in place of payload" in d["decision"]["stopped"]
    assert "in place of payload" in (tmp_path / "rep" / "report.html").read_text()


def test_a_payload_beyond_a_plausible_mass_error_stays_named(cli, tmp_path):
    d = _diagnose(cli, _record(cli, tmp_path, "--effect", "payload:joint=j2,mass=14"), tmp_path / "rep")
    assert d["verdict"] == "discrepancy", d["decision"]
    (s,) = d["selected"]
    assert s["effect"] == "payload" and s["params"]["mass"] == pytest.approx(14.0, rel=0.1)
    assert d["calibration"]["stand_ins"] == []
