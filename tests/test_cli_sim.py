"""The hydrohil sim commands: contracts (JSON keys, CSV columns) and bad input."""

import json

import numpy as np
import pytest

from sim_core.dataset import read_csv


def test_robots_json(cli):
    out = json.loads(cli("robots", "--json", check=True).stdout)
    robots = {r["name"]: r for r in out}
    assert set(robots) == {"hydrolek", "mars_nd", "harvester"}
    h = robots["hydrolek"]
    assert [j["name"] for j in h["joints"]] == [f"j{k}" for k in range(1, 8)]
    kinds = [j["actuator"] for j in h["joints"]]
    assert kinds[:5] == ["cylinder"] * 5 and kinds[5] in ("rotary_actuator", "hydraulic_motor")
    assert [j["sensed"] for j in h["joints"]] == [True] * 5 + [False] * 2
    assert all(j["command_voltage_range"] == [-10.0, 10.0] for j in h["joints"])
    assert len(robots["mars_nd"]["joints"]) == 14
    hv = {j["name"]: j for j in robots["harvester"]["joints"]}
    assert hv["swing"]["actuator"] == "hydraulic_motor" and hv["boom"]["actuator"] == "cylinder"
    assert robots["harvester"]["passive_joints"] == ["hooke_pitch", "hooke_roll"]


def test_effects_json_catalog(cli):
    cat = json.loads(cli("effects", "--json", check=True).stdout)
    names = [e["name"] for e in cat]
    catalog16 = ["deadband", "valve_asymmetry", "spool_lag", "delay", "leakage", "coulomb_friction",
                 "backlash", "area_ratio", "flow_saturation", "line_dynamics", "joint_compliance",
                 "payload", "sensor_offset", "sensor_gain", "hysteresis", "bulk_modulus"]
    # the research catalog's 16, in its order, and the effects added since (one file each)
    assert [n for n in names if n in catalog16] == catalog16
    assert {"stribeck_friction", "valve_offset", "pump_limit"} <= set(names) and len(set(names)) == len(names) == 19
    for e in cat:
        assert e["description"] and e["citation"] and e["scope"] in ("per-joint", "global")
        assert e["parameters"]
        for p in e["parameters"]:
            assert {"name", "unit", "default", "lower", "upper"} <= set(p)
            assert p["lower"] <= p["default"] <= p["upper"]
    scopes = {e["name"]: e["scope"] for e in cat}
    assert scopes["bulk_modulus"] == scopes["pump_limit"] == "global"


def test_excite_writes_a_multilevel_prbs(cli, tmp_path):
    out = tmp_path / "in.csv"
    cli("excite", "--robot", "hydrolek", "--joint", "j2", "--levels", "5", "--amplitude", "6", "--duration", "20",
        "--rate", "200", "--seed", "3", "--out", out, check=True)
    ds = read_csv(out)
    assert ds.columns == ["time"] + [f"u_j{k}" for k in range(1, 8)]
    assert len(ds) == 4001 and ds.time[-1] == pytest.approx(20.0)
    u = ds["u_j2"]
    assert set(np.unique(u)) <= set(np.linspace(-6, 6, 5)) and len(np.unique(u)) >= 4
    for j in ("u_j1", "u_j3", "u_j7"):
        assert not ds[j].any()
    again = tmp_path / "again.csv"
    cli("excite", "--robot", "hydrolek", "--joint", "j2", "--levels", "5", "--amplitude", "6", "--duration", "20",
        "--rate", "200", "--seed", "3", "--out", again, check=True)
    assert again.read_text() == out.read_text()


def test_excite_guard_keeps_the_joint_off_its_stops(cli, tmp_path, plants):
    from sim_core.simulator import Simulator

    plant = plants("hydrolek")
    lo, hi = plant.tree.lower[1], plant.tree.upper[1]
    for guard in (True, False):
        out = tmp_path / f"g{guard}.csv"
        args = ["excite", "--robot", "hydrolek", "--joint", "j2", "--amplitude", "8", "--duration", "60",
                "--rate", "100", "--seed", "2", "--out", out]
        cli(*(args + ([] if guard else ["--no-guard"])), check=True)
        ds = read_csv(out)
        traj = Simulator(plant.create_context()).run(ds.time, ds.data[:, 1:])
        q = traj.q[:, 1]
        on_stop = np.mean((q > hi - 0.01) | (q < lo + 0.01))
        if guard:
            assert on_stop == 0.0
        else:
            assert on_stop > 0.05   # without the guard this PRBS drives the shoulder into a stop


def test_simulate_end_to_end(cli, tmp_path):
    inp = tmp_path / "in.csv"
    cli("excite", "--robot", "hydrolek", "--joint", "j2", "--duration", "5", "--rate", "200", "--out", inp, check=True)
    out = tmp_path / "out.csv"
    cli("simulate", "--robot", "hydrolek", "--input", inp, "--out", out, "--noise-angle", "0", check=True)
    ds = read_csv(out)
    expected = (["time"] + [f"u_j{k}" for k in range(1, 8)] + [f"q_j{k}" for k in range(1, 6)]
                + [f"p_j{k}_{c}" for k in range(1, 8) for c in "ab"])
    assert ds.columns == expected
    src = read_csv(inp)
    np.testing.assert_array_equal(ds.time, src.time)
    np.testing.assert_array_equal(ds["u_j2"], src["u_j2"])
    assert np.ptp(ds["q_j2"]) > 0.05 and np.ptp(ds["q_j1"]) < 1e-3
    assert 1e6 < ds["p_j2_a"].mean() < 14e6


def test_simulate_effect_params_and_noise(cli, tmp_path):
    inp = tmp_path / "in.csv"
    cli("excite", "--robot", "hydrolek", "--joint", "j2", "--duration", "5", "--rate", "200", "--out", inp, check=True)
    base, offs, noisy = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.csv"
    cli("simulate", "--robot", "hydrolek", "--input", inp, "--out", base, "--noise-angle", "0", check=True)
    cli("simulate", "--robot", "hydrolek", "--input", inp, "--out", offs, "--noise-angle", "0",
        "--effect", "sensor_offset:joint=j2,offset=0.05", check=True)
    d = read_csv(offs)["q_j2"] - read_csv(base)["q_j2"]
    assert np.allclose(d, 0.05, atol=2e-4)
    params = tmp_path / "p.toml"
    params.write_text('robot = "hydrolek"\n[parameters]\n"joints.j2.sensor.B" = -2.8\n'
                      '[[effects]]\nname = "sensor_offset"\njoint = "j2"\noffset = 0.05\n')
    via_file = tmp_path / "f.csv"
    cli("simulate", "--robot", "hydrolek", "--input", inp, "--out", via_file, "--noise-angle", "0",
        "--params", params, check=True)
    assert np.allclose(read_csv(via_file)["q_j2"], read_csv(offs)["q_j2"], atol=2e-4)
    cli("simulate", "--robot", "hydrolek", "--input", inp, "--out", noisy, "--noise-angle", "0.002", "--seed", "4", check=True)
    resid = read_csv(noisy)["q_j2"] - read_csv(base)["q_j2"]
    assert np.std(resid) == pytest.approx(0.002, rel=0.1)


BAD_INPUTS = [
    ("time_missing", "t,u_j2\n0,0\n0.01,1\n", "missing column 'time'"),
    ("not_monotonic", "time,u_j2\n0,0\n0.01,1\n0.01,1\n", "column 'time': row 3"),
    ("unknown_joint", "time,u_j9\n0,0\n0.01,1\n", "column 'u_j9': unknown joint 'j9'"),
    ("nan", "time,u_j2\n0,0\n0.01,nan\n", "column 'u_j2': row 2"),
    ("text", "time,u_j2\n0,0\n0.01,abc\n", "column 'u_j2': row 2"),
    ("over_range", "time,u_j2\n0,0\n0.01,12.5\n", "column 'u_j2': row 2 (line 3): 12.5 V is outside"),
    ("strange_column", "time,u_j2,banana\n0,0,1\n0.01,1,2\n", "column 'banana'"),
    ("short_row", "time,u_j2\n0,0\n0.01\n", "row 2"),
]


@pytest.mark.parametrize("name,content,message", BAD_INPUTS, ids=[b[0] for b in BAD_INPUTS])
def test_simulate_rejects_bad_input_by_name(cli, tmp_path, name, content, message):
    inp = tmp_path / "bad.csv"
    inp.write_text(content)
    proc = cli("simulate", "--robot", "hydrolek", "--input", inp, "--out", tmp_path / "o.csv")
    assert proc.returncode != 0
    assert message in proc.stderr, proc.stderr
    assert not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize("args,message", [
    (["--effect", "warp:joint=j2"], "unknown effect 'warp'"),
    (["--effect", "deadband:joint=j2,wdth=1"], "unknown parameter(s) wdth"),
    (["--effect", "deadband:joint=j99,width=1"], "unknown joint 'j99'"),
    (["--set", "joints.j2.valve.flux=3"], "unknown parameter 'flux'"),
    (["--set", "supply.pressure=-5"], "supply.pressure"),
    (["--robot", "robocop"], "unknown robot 'robocop'"),
])
def test_simulate_rejects_bad_model_options(cli, tmp_path, args, message):
    inp = tmp_path / "in.csv"
    inp.write_text("time,u_j2\n0,0\n0.01,1\n")
    base = ["simulate", "--input", inp, "--out", tmp_path / "o.csv"]
    if "--robot" not in args:
        base += ["--robot", "hydrolek"]
    proc = cli(*(base + args))
    assert proc.returncode != 0 and message in proc.stderr, proc.stderr
