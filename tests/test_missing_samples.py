"""Missing samples in a log (sim_core/ingest/missing.py): the filling rules on short arrays (no
simulation), then a user's rig log with empty, NaN and #N/A cells through ``import`` and
``diagnose``. The rows left empty are chosen here, so the expected rows and filled values come from
the test, not from the code under test."""

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from conftest import run_cli
from rig_records import closed_loop_record
from sim_core.dataset import read_dataset
from sim_core.ingest.missing import MAX_RUN, filled, is_missing
from sim_core.model.spec import load_robot

NAN = np.nan


def test_a_measured_run_is_filled_by_the_line_between_its_neighbours_and_an_end_by_the_nearest():
    y = np.array([NAN, 1.0, 2.0, NAN, NAN, NAN, 6.0, 7.0, NAN])
    np.testing.assert_array_equal(filled(y, "line"), [1.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 7.0])


def test_a_command_is_held_at_its_value_before_and_a_first_missing_one_takes_the_first_sample():
    u = np.array([NAN, 2.0, NAN, NAN, -3.0, NAN])
    np.testing.assert_array_equal(filled(u, "hold"), [2.0, 2.0, 2.0, 2.0, -3.0, -3.0])


def test_a_time_carries_its_period_on_past_the_ends():
    t = np.array([NAN, NAN, 0.04, 0.06, NAN, 0.10, NAN])
    np.testing.assert_allclose(filled(t, "carry"), [0.0, 0.02, 0.04, 0.06, 0.08, 0.10, 0.12], atol=1e-15)


def test_the_cells_a_logger_writes_for_no_sample_and_the_ones_it_does_not():
    for cell in ("", " ", "nan", "NaN", "-nan", "NA", "n/a", "#N/A", "null", "None"):
        assert is_missing(cell), cell
    for cell in ("0", "inf", "-", "abc", "1e-3"):
        assert not is_missing(cell), cell


# ---- the user's way: a rig log with missed reads ----------------------------------------------------

# column (0 time, 1 position volts, 2 command) -> {0-based row: what the logger wrote there instead of a number}
HOLES = {0: {1200: ""}, 1: {0: "", 700: "", 1501: "NaN", 1502: "#N/A", 1503: "nan"}, 2: {900: "NA"}}
READ = ["--no-header", "--column", "time=0", "--column", "q_lift=1:sensor_volts", "--column", "u_lift=2"]


def write_with_holes(rows: np.ndarray, path, holes: dict[int, dict[int, str]]) -> None:
    with open(path, "w") as fh:
        for r, (t, v, u) in enumerate(rows):
            cells = [f"{t:.4f}", f"{v:.4f}", f"{u:.3f}"]
            for c, where in holes.items():
                if r in where:
                    cells[c] = where[r]
            fh.write(",".join(cells) + "\n")


def logged(path) -> np.ndarray:
    """The log as written, its holes NaN (read here, not by the code under test)."""
    def number(cell):
        return float(cell) if cell.strip().lower() not in ("", "nan", "na", "#n/a") else np.nan
    return np.array([[number(c) for c in line.split(",")] for line in Path(path).read_text().splitlines()])


@pytest.fixture(scope="module")
def holed_log(tmp_path_factory):
    """The cylinder rig's clean closed-loop log (valve +20 %, supply -15 %, start off) with the cells
    of HOLES left empty or written NaN, NA, #N/A by the logger."""
    d = tmp_path_factory.mktemp("missing")
    run_cli("rig", "new", "cylinder", "--out", d / "rig", check=True)
    spec = load_robot(d / "rig")
    rows, _ = closed_loop_record(d / "rig", hidden=None, seed=5, start_offset=0.025,
                                 off={"joints.lift.valve.rated_flow": 1.2, "supply.pressure": 0.85})
    write_with_holes(rows, d / "log.csv", HOLES)
    return d, spec, rows


def test_a_missing_sample_is_refused_by_default_naming_the_column_and_row_and_the_option(cli, holed_log):
    d, _, _ = holed_log
    proc = cli("import", d / "log.csv", "--robot", d / "rig", "--out", d / "refused.csv", *READ)
    assert proc.returncode == 2
    assert "column q_lift (column 1): row 1 (line 1): is empty (a missing value; --missing repair" in proc.stderr
    assert not (d / "refused.csv").exists()


def test_repair_fills_each_missed_read_as_its_column_needs_and_says_where(cli, holed_log):
    d, spec, _ = holed_log
    proc = cli("import", d / "log.csv", "--robot", d / "rig", "--out", d / "rec.csv", *READ, "--missing", "repair")
    assert proc.returncode == 0, proc.stderr
    assert "MISSING 5 sample(s) filled" in proc.stdout
    side = json.loads((d / "rec.csv.import.json").read_text())
    cols = side["columns"]
    assert cols["q_lift"]["missing"] == {"samples": 5, "runs": [[1, 1], [701, 701], [1502, 1504]],
                                         "filled_by": "interpolation"}
    assert cols["u_lift"]["missing"] == {"samples": 1, "runs": [[901, 901]], "filled_by": "the value before"}
    assert cols["time"]["missing"]["runs"] == [[1201, 1201]]
    assert side["options"]["missing"] == "repair"
    raw = logged(d / "log.csv")
    ds = read_dataset(d / "rec.csv")
    A, B = spec.get("joints.lift.sensor.A"), spec.get("joints.lift.sensor.B")
    t, v, u = raw[:, 0], raw[:, 1], raw[:, 2]
    q = ds["q_lift"]
    assert q[0] == pytest.approx(A * v[1] + B, abs=1e-12)                           # the first: its neighbour
    assert q[700] == pytest.approx(A * (v[699] + v[701]) / 2 + B, abs=1e-12)
    for k in (1, 2, 3):                                                              # a run of 3: the line across it
        assert q[1500 + k] == pytest.approx(A * (v[1500] + k / 4 * (v[1504] - v[1500])) + B, abs=1e-12)
    assert ds["u_lift"][900] == u[899]
    assert ds.time[1200] == pytest.approx((t[1199] + t[1201]) / 2 - t[0], abs=1e-12)
    clean = np.setdiff1d(np.arange(len(v)), [0, 700, 1501, 1502, 1503])
    np.testing.assert_allclose(q[clean], A * v[clean] + B, atol=1e-12)


def test_a_run_longer_than_three_is_a_gap_and_is_refused_with_its_rows(cli, holed_log, tmp_path):
    d, _, _ = holed_log
    lines = (d / "log.csv").read_text().splitlines()
    for r in range(2000, 2000 + MAX_RUN + 1):
        t, _, u = lines[r].split(",")
        lines[r] = f"{t},,{u}"
    (tmp_path / "gap.csv").write_text("\n".join(lines) + "\n")
    proc = cli("import", tmp_path / "gap.csv", "--robot", d / "rig", "--out", tmp_path / "gap_rec.csv", *READ,
               "--missing", "repair")
    assert proc.returncode == 2
    assert f"row 2001 (line 2001) to row 2004 (line 2004): {MAX_RUN + 1} missing samples in a row" in proc.stderr


def test_diagnose_reads_the_repaired_log_to_its_noise_ceiling(cli, holed_log):
    """``diagnose`` takes the option too: filled as above, the nominal rig model fits the log to its
    noise ceiling, nothing is named, and the diagnosis's notes say what was filled."""
    d, _, _ = holed_log
    rep = d / "rep"
    proc = cli("diagnose", "--robot", d / "rig", d / "log.csv", *READ, "--missing", "repair", "--report", rep, "--quiet")
    assert proc.returncode == 0, proc.stderr
    out = json.loads((rep / "diagnosis.json").read_text())
    assert out["verdict"] == "no_significant_discrepancy" and not out["selected"]
    assert any("missing sample(s)" in n for n in out["data"]["notes"])
    assert out["baseline"]["fit"]["lift"] > out["data"]["fit_ceiling"]["lift"] - 1.0


def test_a_parquet_log_with_nulls_reads_the_same_way(cli, holed_log, tmp_path):
    d, spec, rows = holed_log
    A, B = spec.get("joints.lift.sensor.A"), spec.get("joints.lift.sensor.B")
    q = A * rows[:, 1] + B
    table = pa.table({"time": rows[:, 0], "u_lift": rows[:, 2],
                      "q_lift": pa.array([None if k in (400, 401) else float(x) for k, x in enumerate(q)], pa.float64())})
    pq.write_table(table, tmp_path / "log.parquet")
    proc = cli("import", tmp_path / "log.parquet", "--robot", d / "rig", "--out", tmp_path / "pq.csv")
    assert proc.returncode == 2 and "column 'q_lift': row 401: empty (a missing value; --missing repair" in proc.stderr
    proc = cli("import", tmp_path / "log.parquet", "--robot", d / "rig", "--out", tmp_path / "pq.csv", "--missing", "repair")
    assert proc.returncode == 0, proc.stderr
    got = read_dataset(tmp_path / "pq.csv")["q_lift"]
    np.testing.assert_allclose(got[[400, 401]], q[399] + np.array([1, 2]) / 3 * (q[402] - q[399]), atol=1e-12)
    np.testing.assert_allclose(np.delete(got, [400, 401]), np.delete(q, [400, 401]), atol=1e-12)
