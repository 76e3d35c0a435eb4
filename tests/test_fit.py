"""hydrohil fit: output-error calibration of nominal parameters, with uncertainties, to a --params file."""

import json
import tomllib

import pytest

from sim_core.dataset import read_csv
from sim_core.identification.metrics import nrmse_fit


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    """A hydrolek shoulder record whose valve passes 8 % more than the nominal model says and whose
    potentiometer reads 0.03 rad high (a wrong calibration offset B)."""
    from conftest import run_cli

    d = tmp_path_factory.mktemp("fit")
    run_cli("excite", "--robot", "hydrolek", "--joint", "j2", "--duration", 20, "--seed", 11, "--out", d / "in.csv", check=True)
    run_cli("simulate", "--robot", "hydrolek", "--input", d / "in.csv", "--out", d / "meas.csv",
            "--set", "joints.j2.valve.rated_flow=4.5036e-5", "--effect", "sensor_offset:joint=j2,offset=0.03",
            "--noise-angle", 3e-4, "--seed", 2, check=True)
    return d


def test_fit_recovers_the_flow_gain_and_the_calibration(cli, record, tmp_path):
    out = tmp_path / "p.toml"
    proc = cli("fit", "--robot", "hydrolek", record / "meas.csv", "--free", "joints.j2.valve.rated_flow",
               "effects.sensor_offset.j2.offset", "--out", out, "--json")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    p = res["parameters"]
    assert p["joints.j2.valve.rated_flow"]["value"] == pytest.approx(4.5036e-5, rel=0.01)
    assert p["effects.sensor_offset.j2.offset"]["value"] == pytest.approx(0.03, abs=2e-3)
    assert res["switched_on"] == ["sensor_offset@j2"]
    for v in p.values():
        lo, hi = v["ci95"]
        assert lo < v["value"] < hi and v["sigma"] > 0
    fit = res["fit"][str(record / "meas.csv")]["j2"]
    assert fit["angle"]["after"] > 99.0 > fit["angle"]["before"]
    assert fit["angle"]["spread"] < 0.5 and "velocity" in fit and "pressure" in fit
    # the file is a --params file: simulating with it reproduces the record
    data = tomllib.loads(out.read_text())
    assert data["robot"] == "hydrolek" and set(data["parameters"]) == {"joints.j2.valve.rated_flow"}
    assert [e["name"] for e in data["effects"]] == ["sensor_offset"]
    cli("simulate", "--robot", "hydrolek", "--input", record / "in.csv", "--out", tmp_path / "sim.csv",
        "--params", out, check=True)
    y = read_csv(record / "meas.csv")["q_j2"]
    assert nrmse_fit(y, read_csv(tmp_path / "sim.csv")["q_j2"]) > 99.0


def test_fit_default_frees_the_flow_gain(cli, record, tmp_path):
    proc = cli("fit", "--robot", "hydrolek", record / "meas.csv", "--out", tmp_path / "p.toml")
    assert proc.returncode == 0, proc.stderr
    assert "joints.j2.valve.rated_flow" in proc.stdout and "fit on" in proc.stdout


@pytest.mark.parametrize("free,needle", [
    ("joints.j2.valve.nonsense", "nonsense"),
    ("joints.j9.valve.rated_flow", "j9"),
    ("effects.deadband.j2.depth", "no parameter 'depth'"),
    ("joints.j2.sensor.B", "cancel"),
    ("joints.j2.cylinder.base_mount", "not a scalar"),
    ("joints.j2.sensor.noise", "noise"),
])
def test_fit_bad_free_parameters(cli, record, tmp_path, free, needle):
    proc = cli("fit", "--robot", "hydrolek", record / "meas.csv", "--free", free, "--out", tmp_path / "p.toml")
    assert proc.returncode == 2
    assert "hydrohil fit: error:" in proc.stderr and needle in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "p.toml").exists()


def test_fit_refuses_a_negative_worker_count(cli, record, tmp_path):
    proc = cli("fit", "--robot", "hydrolek", record / "meas.csv", "--workers", "-1", "--out", tmp_path / "p.toml")
    assert proc.returncode == 2
    assert "hydrohil fit: error:" in proc.stderr and "--workers -1" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "p.toml").exists()


def test_fit_effect_parameter_of_a_nominal_effect(cli, tmp_path):
    """The harvester's deadband is part of its model: its width can be calibrated like the pots."""
    cli("excite", "--robot", "harvester", "--joint", "boom", "--duration", 20, "--seed", 3, "--out", tmp_path / "in.csv", check=True)
    cli("simulate", "--robot", "harvester", "--input", tmp_path / "in.csv", "--out", tmp_path / "m.csv",
        "--effect", "deadband:joint=boom,width=1.5", "--noise-angle", 3e-4, check=True)
    proc = cli("fit", "--robot", "harvester", tmp_path / "m.csv", "--free", "effects.deadband.boom.width",
               "--out", tmp_path / "p.toml", "--json")
    assert proc.returncode == 0, proc.stderr
    w = json.loads(proc.stdout)["parameters"]["effects.deadband.boom.width"]["value"]
    assert w == pytest.approx(1.5, rel=0.03)
    data = tomllib.loads((tmp_path / "p.toml").read_text())
    assert any(e["name"] == "deadband" and e["joint"] == "boom" and e["width"] == pytest.approx(w) for e in data["effects"])
