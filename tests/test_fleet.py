"""hydrohil diagnose-fleet and diagnose --backend ray, on a real Ray the test starts (num_cpus=2).

The records are made like the diagnose tests' (``hydrohil excite`` then ``hydrohil simulate`` with a
hidden deadband on hydrolek j2, whose width grows from record to record as their dated names go on),
short (20 s at 100 Hz) so that the module stays within a few minutes. The same fleet goes through
the local pool and through Ray; the fits are deterministic, so every diagnosis must be identical.
"""

import csv
import json
import os
import re
import shutil
import subprocess
import sys
from datetime import date

import numpy as np
import pytest
import ray

from conftest import ROOT

pytestmark = pytest.mark.realtime

# the helper task below travels to Ray's workers by value (tests/ is not on their path)
ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])

WIDTHS = {"2024-01-05": 0.5, "2024-02-05": 0.8, "2024-03-05": 1.1}   # hidden deadband (V) per record date
BAD = "bench_2024-02-20.csv"       # a record whose column the robot does not have: fails, the others go on
GOOD = [f"crane_{d}" for d in WIDTHS]


def cli(*args, timeout=900):
    return subprocess.run([sys.executable, "-m", "sim_core.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def ok(proc):
    assert proc.returncode == 0, proc.stderr
    return proc


@pytest.fixture(scope="module")
def ray_address():
    """A real Ray of 2 CPUs for this module; the commands connect to it with --address."""
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        yield ray.get_runtime_context().gcs_address
    finally:
        ray.shutdown()


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    where = tmp_path_factory.mktemp("records")
    ok(cli("excite", "--robot", "hydrolek", "--joint", "j2", "--duration", 20, "--rate", 100, "--seed", 5,
           "--out", where / "in.csv"))
    paths = []
    for k, (day, width) in enumerate(WIDTHS.items()):
        out = where / f"crane_{day}.csv"
        ok(cli("simulate", "--robot", "hydrolek", "--input", where / "in.csv", "--out", out, "--noise-angle", 3e-4,
               "--seed", 10 + k, "--effect", f"deadband:joint=j2,width={width}"))
        paths.append(out)
    bad = where / BAD
    bad.write_text("time,u_j2,q_j9\n" + "".join(f"{0.01 * i:.2f},1,0\n" for i in range(400)))
    paths.insert(2, bad)            # between good records: the ones after it must still be diagnosed
    return paths


@pytest.fixture(scope="module")
def fleets(records, ray_address, tmp_path_factory):
    """The same fleet through the local pool and through Ray (2 at a time each)."""
    out = tmp_path_factory.mktemp("fleets")
    runs = {}
    for backend, extra in (("local", []), ("ray", ["--address", ray_address])):
        proc = cli("diagnose-fleet", *records, "--robot", "hydrolek", "--report", out / backend, "--backend", backend,
                   "--workers", 2, *extra)
        runs[backend] = (proc, out / backend)
    return runs


def fleet_json(d):
    return json.loads((d / "fleet.json").read_text())


def without_timings(diag):
    diag = dict(diag)
    diag.pop("timings_s")
    return diag


def test_local_and_ray_give_identical_diagnoses(fleets):
    for backend, (proc, d) in fleets.items():
        assert proc.returncode == 1, proc.stderr      # one record failed: said by the exit status
        assert "Traceback" not in proc.stderr
    local, on_ray = fleets["local"][1], fleets["ray"][1]
    assert "on ray at" in fleets["ray"][0].stderr
    for name in GOOD:
        for backend, (proc, d) in fleets.items():
            assert (d / name / "diagnosis.json").is_file(), proc.stderr
        a = json.loads((local / name / "diagnosis.json").read_text())
        b = json.loads((on_ray / name / "diagnosis.json").read_text())
        assert without_timings(a) == without_timings(b), name
        assert (local / name / "extended.toml").read_bytes() == (on_ray / name / "extended.toml").read_bytes()
        assert (on_ray / name / "report.html").stat().st_size > 10_000
    rows = {b: {r["record"]: r for r in fleet_json(d)["records"]} for b, (_, d) in fleets.items()}
    for name in GOOD:
        ra, rb = rows["local"][name], rows["ray"][name]
        assert ra["status"] == rb["status"] == "diagnosed"
        assert ra["verdict"] == rb["verdict"] == "discrepancy"
        assert ra["effects"] == rb["effects"]
        (e,) = ra["effects"]
        assert (e["effect"], e["joint"]) == ("deadband", "j2")
        truth = WIDTHS[name.removeprefix("crane_")]
        assert e["params"]["width"] == pytest.approx(truth, rel=0.1)
        lo, hi = e["ci95"]["width"]
        assert lo <= e["params"]["width"] <= hi
        assert e["units"] == {"width": "V"}
        assert ra["fit_after"]["j2"] > ra["fit_before"]["j2"]


def test_progress_says_records_done_running_and_time_left(fleets):
    err = fleets["ray"][0].stderr
    lines = [ln for ln in err.splitlines() if re.match(r"\[\s*\d+/\d+\] ", ln)]
    assert len(lines) == len(GOOD) + 1
    assert lines[0].startswith("[1/4] ") and lines[-1].startswith("[4/4] ")
    assert any("running: " in ln for ln in lines[:-1])
    assert any(" left" in ln for ln in lines[:-1])
    for name in GOOD:       # the current record is said when it starts, before its (long) diagnosis ends
        assert err.index(f"started {name} ") < err.index(f"] {name}: ")
    assert "records per hour" in err


def test_a_failing_record_does_not_stop_the_fleet(fleets):
    for backend, (proc, d) in fleets.items():
        data = fleet_json(d)
        rows = {r["record"]: r for r in data["records"]}
        assert list(rows) == ["crane_2024-01-05", "crane_2024-02-05", "bench_2024-02-20", "crane_2024-03-05"]
        bad = rows["bench_2024-02-20"]
        assert bad["status"] == "failed"
        assert BAD in bad["error"] and "q_j9" in bad["error"]
        assert not (d / "bench_2024-02-20" / "diagnosis.json").exists()
        assert all(rows[n]["status"] == "diagnosed" for n in GOOD)
        assert data["totals"]["failed"] == 1 and data["totals"]["diagnosed"] == 3
        with open(d / "fleet.csv") as fh:
            lines = list(csv.DictReader(fh))
        assert [ln["record"] for ln in lines] == list(rows)
        assert "q_j9" in lines[2]["error"] and lines[2]["status"] == "failed"
        html = (d / "index.html").read_text()
        assert "q_j9" in html and "bench_2024-02-20" in html
        for n in GOOD:
            assert f"href='{n}/report.html'" in html


def test_fleet_view_follows_the_growing_deadband(fleets):
    data = fleet_json(fleets["local"][1])
    (view,) = [v for v in data["effects"] if v["label"] == "deadband@j2"]
    assert view["records"] == GOOD
    pts = view["params"]["width"]
    assert [p["date"] for p in pts] == list(WIDTHS)
    assert all(p["named"] for p in pts)
    # the truth's own least-squares slope over the same dates (V per day)
    t = np.array([date.fromisoformat(d).toordinal() for d in WIDTHS], float)
    truth_slope = np.polyfit(t, list(WIDTHS.values()), 1)[0]
    tr = view["trend"]["width"]
    assert tr["rising"] and tr["ci95"][0] > 0
    assert tr["per_day"] == pytest.approx(truth_slope, rel=0.1)
    with open(fleets["local"][1] / "fleet.csv") as fh:
        lines = {ln["record"]: ln for ln in csv.DictReader(fh)}
    for p in pts:
        assert float(lines[p["record"]]["deadband@j2.width"]) == pytest.approx(p["value"], rel=1e-7)
    assert view["units"] == {"width": "V"}
    html = (fleets["local"][1] / "index.html").read_text()
    assert "width rises" in html and " V per day" in html and "<th>width (V)</th>" in html
    assert re.search(r"width=[0-9.]+ \[[0-9.]+, [0-9.]+\] V", html)


def test_parameter_units_follow_the_joint_kind():
    from sim_core.fleet.rows import unit, with_units
    from sim_core.fleet.runner import prismatic_joints
    from sim_core.model.spec import load_robot

    assert prismatic_joints(load_robot(ROOT / "tests/data/import/slide/robot.toml")) == {"lift"}
    assert prismatic_joints(load_robot("hydrolek")) == frozenset()
    assert (unit("coulomb_friction", "torque"), unit("coulomb_friction", "torque", True)) == ("N m", "N")
    assert (unit("backlash", "width"), unit("backlash", "width", True)) == ("rad", "m")
    assert unit("deadband", "width", True) == "V"           # one unit for both kinds
    row = {"record": "r", "effects": [{"effect": "coulomb_friction", "joint": "lift", "params": {"torque": 1.0}},
                                      {"effect": "backlash", "joint": "j2", "params": {"width": 0.01}}]}
    (out,) = with_units([row], frozenset({"lift"}))
    assert [e["units"] for e in out["effects"]] == [{"torque": "N"}, {"width": "rad"}]


def test_rerun_skips_unchanged_records(fleets, records, tmp_path):
    d = tmp_path / "fleet"
    shutil.copytree(fleets["local"][1], d)
    stamps = {n: (d / n / "diagnosis.json").stat().st_mtime_ns for n in GOOD}
    proc = cli("diagnose-fleet", *records, "--robot", "hydrolek", "--report", d, "--workers", 2)
    assert proc.returncode == 1, proc.stderr
    rows = {r["record"]: r for r in fleet_json(d)["records"]}
    assert all(rows[n]["status"] == "unchanged" for n in GOOD)
    assert rows["bench_2024-02-20"]["status"] == "failed"         # failures are tried again
    assert {n: (d / n / "diagnosis.json").stat().st_mtime_ns for n in GOOD} == stamps
    assert "[1/1] bench_2024-02-20" in proc.stderr
    # one record's bytes change: only that one is diagnosed again, and says why
    changed = tmp_path / records[1].name
    text = records[1].read_text().splitlines()
    changed.write_text("\n".join(text[:-1]) + "\n")               # its last sample dropped
    again = [records[0], changed, records[3]]
    proc = cli("diagnose-fleet", *again, "--robot", "hydrolek", "--report", d, "--workers", 2)
    assert proc.returncode == 0, proc.stderr
    rows = {r["record"]: r for r in fleet_json(d)["records"]}
    assert rows["crane_2024-02-05"]["status"] == "diagnosed"
    assert rows["crane_2024-02-05"]["rerun_because"] == ["record"]
    assert rows["crane_2024-01-05"]["status"] == rows["crane_2024-03-05"]["status"] == "unchanged"
    assert (d / "crane_2024-02-05" / "diagnosis.json").stat().st_mtime_ns != stamps["crane_2024-02-05"]
    assert list(rows) == ["crane_2024-01-05", "crane_2024-02-05", "crane_2024-03-05"]


def test_diagnose_backend_ray_matches_the_local_pool(records, ray_address, tmp_path):
    rec = records[0]
    ok(cli("diagnose", "--robot", "hydrolek", rec, "--report", tmp_path / "local", "--quiet", "--workers", 2))
    proc = ok(cli("diagnose", "--robot", "hydrolek", rec, "--report", tmp_path / "ray", "--backend", "ray",
                  "--address", ray_address))
    assert "candidate fits on ray at" in proc.stderr
    a = json.loads((tmp_path / "local" / "diagnosis.json").read_text())
    b = json.loads((tmp_path / "ray" / "diagnosis.json").read_text())
    assert a["verdict"] == "discrepancy"
    assert without_timings(a) == without_timings(b)


FAILS_ON_SOME = """
import os


def fails_on_some(shared, item):
    if item == shared["raise"]:
        raise ValueError(f"item {item} is bad")
    if item == shared["crash"]:
        os._exit(3)                 # the worker process dies
    return item * shared["factor"]
"""
exec(FAILS_ON_SOME)     # noqa: S102  (the same function here, for Ray, and in the local pool's script below)

LOCAL_MAP = FAILS_ON_SOME + """
import json, sys
from sim_core.backends import open_backend

b = open_backend("local", workers=2)
runs = [[{"item": o.item, "value": o.value, "error": type(o.error).__name__ if o.error else None,
          "message": str(o.error) if o.error else None, "first": o.task.get("first")} for o in
         b.map(fails_on_some, shared, range(8))]
        for shared in ({"raise": 2, "crash": None, "factor": 10}, {"raise": None, "crash": 5, "factor": 10})]
print(json.dumps({"slots": b.slots, "runs": runs}))
"""


def check_outcomes(by: dict, slots: int, *, raised=None, crashed=None, isolated: bool):
    """A task that raises gets its own exception back; one whose worker dies gets an error; the rest
    of the items come back with their values (a local pool may lose the other tasks in flight with
    a crash: its pool breaks; Ray isolates every task)."""
    assert sorted(by) == list(range(8))
    if raised is not None:
        assert by[raised]["error"] == "ValueError" and f"item {raised} is bad" in by[raised]["message"]
    if crashed is not None:
        assert by[crashed]["error"] is not None and by[crashed]["value"] is None
    good = [i for i in by if by[i]["error"] is None]
    assert all(by[i]["value"] == 10 * i for i in good)
    lost = set(range(8)) - set(good) - {raised, crashed}
    assert not lost if isolated or crashed is None else len(lost) <= slots - 1
    assert any(by[i]["first"] for i in good)


def test_local_backend_keeps_going_after_a_task_fails():
    """In its own process: a local pool forked from a process that runs Ray would inherit Ray's threads."""
    proc = subprocess.run([sys.executable, "-c", LOCAL_MAP], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    raised, crashed = ({o["item"]: o for o in run} for run in res["runs"])
    check_outcomes(raised, res["slots"], raised=2, isolated=False)
    check_outcomes(crashed, res["slots"], crashed=5, isolated=False)


def test_ray_backend_keeps_going_after_a_task_fails(ray_address):
    from sim_core.backends import open_backend

    b = open_backend("ray", workers=2, address=ray_address)
    try:
        out = list(b.map(fails_on_some, {"raise": 2, "crash": 5, "factor": 10}, range(8)))   # noqa: F821
    finally:
        b.close()
    assert ray.is_initialized()             # the backend did not shut down the Ray it did not start
    by = {o.item: {"value": o.value, "error": type(o.error).__name__ if o.error else None,
                   "message": str(o.error) if o.error else None, "first": o.task.get("first")} for o in out}
    check_outcomes(by, b.slots, raised=2, crashed=5, isolated=True)


def test_ray_missing_says_how_to_install(records, tmp_path):
    """Without Ray importable, --backend ray names the extra to install (and nothing runs)."""
    code = ("import sys; sys.modules['ray'] = None; from sim_core.cli import main; sys.exit(main(sys.argv[1:]))")
    for args in (["diagnose-fleet", *records[:1], "--robot", "hydrolek", "--report", tmp_path / "f", "--backend", "ray"],
                 ["diagnose", records[0], "--robot", "hydrolek", "--report", tmp_path / "d", "--backend", "ray"]):
        proc = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, cwd=ROOT,
                              timeout=300)
        assert proc.returncode == 2, proc.stderr
        assert "pip install 'hydrohil[ray]'" in proc.stderr
        assert "Traceback" not in proc.stderr


def test_unreachable_address_is_an_error_not_a_hang(records, tmp_path):
    import socket

    with socket.socket() as s:          # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = cli("diagnose-fleet", records[0], "--robot", "hydrolek", "--report", tmp_path / "f", "--backend", "ray",
               "--address", f"127.0.0.1:{port}", timeout=120)
    assert proc.returncode == 2
    assert f"127.0.0.1:{port}" in proc.stderr and "ray start --head" in proc.stderr
    proc = cli("diagnose-fleet", records[0], "--robot", "hydrolek", "--report", tmp_path / "f", "--address", "auto")
    assert proc.returncode == 2 and "--backend ray" in proc.stderr


def test_the_fleet_replays_the_command_as_told(records, tmp_path):
    """``diagnose-fleet --command-hold`` reaches each record's diagnosis (period_mean: every commanded
    joint, the open-loop records' too, the choice said as given); a wrong value is refused by name."""
    from sim_core.identification import command_hold

    proc = ok(cli("diagnose-fleet", records[0], "--robot", "hydrolek", "--report", tmp_path / "f", "--workers", 1,
                  "--command-hold", "period_mean", "--effects", "deadband"))
    d = json.loads((tmp_path / "f" / records[0].stem / "diagnosis.json").read_text())
    hold = d["closed_loop_evidence"]["command_hold"]
    assert hold["replay"] == command_hold.PERIOD_MEAN and hold["rule"] == command_hold.GIVEN_RULE, proc.stdout
    assert "j2" in hold["joints"]
    bad = cli("diagnose-fleet", records[0], "--robot", "hydrolek", "--report", tmp_path / "g", "--command-hold", "zoh")
    assert bad.returncode == 2 and "--command-hold" in bad.stderr and "Traceback" not in bad.stderr


def test_input_key_parts_follow_what_changes_a_diagnosis(records, tmp_path):
    from sim_core.fleet import FleetOptions
    from sim_core.fleet.inputs import changed_parts, file_digest, input_key, spec_digest
    from sim_core.ingest import ReadOptions
    from sim_core.model.spec import load_robot

    spec = load_robot("hydrolek")
    base = spec_digest(spec)
    assert spec_digest(load_robot("hydrolek")) == base
    other = spec.copy()
    other.set("joints.j2.valve.rated_flow", spec.get("joints.j2.valve.rated_flow") * 1.01)
    assert spec_digest(other) != base
    other = spec.copy()
    other.enable_effect("deadband", "j2", width=0.5)
    assert spec_digest(other) != base
    opts = FleetOptions(spec, ReadOptions())
    assert FleetOptions(spec, ReadOptions(), date_from="stamp").digest() == opts.digest()   # the date is no input
    for changed in (FleetOptions(spec, ReadOptions(), fmt="md"), FleetOptions(spec, ReadOptions(), effects=["deadband"]),
                    FleetOptions(spec, ReadOptions(), initial_pose="data"),
                    FleetOptions(spec, ReadOptions(), command_hold="period_mean"),
                    FleetOptions(spec, ReadOptions(columns=("q_j2=q_j2:deg",)))):
        assert changed.digest() != opts.digest()
    copy = tmp_path / "copy.csv"
    data = bytearray(records[0].read_bytes())
    copy.write_bytes(data)
    assert file_digest(copy) == file_digest(records[0])
    data[-3] = ord("7") if data[-3] != ord("7") else ord("8")
    copy.write_bytes(data)
    assert file_digest(copy) != file_digest(records[0])
    k0 = input_key(records[0], base, opts.digest())
    assert changed_parts(k0, input_key(copy, base, opts.digest())) == ["record"]
    assert changed_parts(k0, input_key(records[0], spec_digest(other), opts.digest())) == ["robot"]
    assert changed_parts(None, k0) == ["new"]


def test_record_dates_from_names_and_columns(tmp_path):
    from datetime import datetime

    from sim_core.fleet.dates import DateError, date_from_column, date_from_name
    from sim_core.ingest import ReadOptions

    assert date_from_name("crane07_2024-03-01.csv") == datetime(2024, 3, 1)
    assert date_from_name("bench_20240301T0610.csv") == datetime(2024, 3, 1, 6, 10)
    assert date_from_name("log_2024_03_05_12-30-15.csv") == datetime(2024, 3, 5, 12, 30, 15)
    assert date_from_name("serial123456789.csv") is None             # digits, but no date
    assert date_from_name("r_20241399_20240102.csv") == datetime(2024, 1, 2)   # month 13 is none
    f = tmp_path / "log.csv"
    f.write_text("# rig 4\nstamp;t;u;q\n2024-03-01T06:10:00+01:00;0;1;0\n2024-03-01T06:10:01+01:00;1;1;0\n")
    opts = ReadOptions(skip_rows=1)
    assert date_from_column(f, "stamp", opts) == datetime(2024, 3, 1, 5, 10)     # UTC
    assert date_from_column(f, "0", opts) == datetime(2024, 3, 1, 5, 10)
    g = tmp_path / "epoch.csv"
    g.write_text("1709273400,0.0,1\n1709273401,0.01,1\n")
    assert date_from_column(g, "0", ReadOptions(no_header=True)) == datetime(2024, 3, 1, 6, 10)
    with pytest.raises(DateError, match="no such column.*stamp, t, u, q"):
        date_from_column(f, "when", opts)
    h = tmp_path / "words.csv"
    h.write_text("stamp,time\nyesterday,0\n")
    with pytest.raises(DateError, match="'yesterday' is neither an ISO 8601 date"):
        date_from_column(h, "stamp", ReadOptions())
