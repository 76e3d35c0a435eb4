"""The dataset files: CSV (fast path, and the slow path that names the bad cell) and Parquet (units and
robot in the schema metadata), through the Python API and the commands that read and write them."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from sim_core.dataset import DatasetError, read_csv, read_dataset, write_csv, write_dataset
from sim_core.ingest import ReadOptions, import_record
from sim_core.model.spec import load_robot

ROOT = Path(__file__).resolve().parent.parent
HYDROHIL = Path(sys.executable).with_name("hydrohil")
SLIDE_TOML = ROOT / "tests" / "data" / "import" / "slide" / "robot.toml"


def hydrohil(*args):
    return subprocess.run([str(HYDROHIL), *map(str, args)], capture_output=True, text=True, timeout=600, cwd=ROOT)


def random_columns(n, seed=0):
    rng = np.random.default_rng(seed)
    return {"time": np.arange(n) * 1e-3, "u_j2": rng.uniform(-10, 10, n), "q_j2": rng.normal(0, 0.3, n),
            "p_j2_a": rng.uniform(0, 2e7, n), "p_j2_b": rng.uniform(0, 2e7, n) * 10.0 ** rng.integers(-12, 12, n)}


def test_csv_written_with_ten_significant_digits_and_read_back(tmp_path):
    cols = random_columns(5000)
    write_csv(tmp_path / "d.csv", cols)
    with open(tmp_path / "d.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == list(cols)
    text = np.array([[float(c) for c in r] for r in rows[1:]])
    expected = np.column_stack([[float(f"{v:.10g}") for v in cols[c]] for c in cols])
    np.testing.assert_array_equal(text, expected)       # what %.10g would print, value for value
    assert max(len(c.lstrip("-").replace(".", "").split("e")[0].lstrip("0")) for r in rows[1:] for c in r) <= 10
    ds = read_csv(tmp_path / "d.csv")
    assert ds.columns == list(cols)
    np.testing.assert_array_equal(ds.data, expected)


def test_parquet_round_trip_is_exact_with_units_and_robot(tmp_path):
    cols = random_columns(3000)
    hydrolek = load_robot("hydrolek")
    write_dataset(tmp_path / "d.parquet", cols, spec=hydrolek)
    ds = read_dataset(tmp_path / "d.parquet")
    assert ds.columns == list(cols)
    np.testing.assert_array_equal(ds.data, np.column_stack(list(cols.values())))
    meta = pq.read_schema(tmp_path / "d.parquet").metadata
    assert json.loads(meta[b"hydrohil.units"]) == {"time": "s", "u_j2": "V", "q_j2": "rad", "p_j2_a": "Pa", "p_j2_b": "Pa"}
    assert meta[b"hydrohil.robot"] == b"hydrolek"
    assert all(f.type == pa.float64() for f in pq.read_schema(tmp_path / "d.parquet"))
    slide = load_robot(SLIDE_TOML)
    write_dataset(tmp_path / "s.parquet", {"time": [0.0, 0.01], "q_lift": [0.1, 0.2]}, spec=slide)
    assert json.loads(pq.read_schema(tmp_path / "s.parquet").metadata[b"hydrohil.units"])["q_lift"] == "m"


def test_fast_path_names_a_bad_cell_deep_in_a_big_file(tmp_path):
    cols = random_columns(20000)
    write_csv(tmp_path / "d.csv", cols)
    lines = (tmp_path / "d.csv").read_text().splitlines()
    cells = lines[15000].split(",")       # data row 15000, line 15001
    cells[2] = "x1"
    lines[15000] = ",".join(cells)
    lines.insert(10, "")                  # a blank line before it: lines count the file's lines
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=r"bad.csv: column 'q_j2': row 15000 \(line 15002\): 'x1' is not a number"):
        read_csv(tmp_path / "bad.csv")
    lines[15001] = lines[15001].replace("x1", "inf")
    (tmp_path / "inf.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=r"column 'q_j2': row 15000 \(line 15002\): inf is not a finite number"):
        read_csv(tmp_path / "inf.csv")
    lines[15001] = lines[15001].replace("inf", "")
    (tmp_path / "empty.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=r"column 'q_j2': row 15000 \(line 15002\): is empty"):
        read_csv(tmp_path / "empty.csv")


def test_blank_lines_and_padded_cells_read_like_the_csv_module(tmp_path):
    rng = np.random.default_rng(3)
    rows = [[f"{v:.6f}" for v in rng.normal(size=4)] for _ in range(300)]
    text = "time, u_j2 ,q_j2,p_j2_a\r\n" + "\r\n".join(" " + ", ".join(r) if i % 7 == 0 else ",".join(r)
                                                      for i, r in enumerate(rows)) + "\r\n\r\n"
    (tmp_path / "d.csv").write_text(text)
    ds = read_csv(tmp_path / "d.csv")
    assert ds.columns == ["time", "u_j2", "q_j2", "p_j2_a"]
    np.testing.assert_array_equal(ds.data, np.array(rows, dtype=float))


@pytest.mark.parametrize("table,message", [
    (pa.table({"time": [0.0, 1.0], "u_j2": ["a", "b"]}), "column 'u_j2' holds string, not numbers"),
    (pa.table({"time": [0.0, 1.0, 2.0], "u_j2": [0.0, None, 1.0]}), r"column 'u_j2': row 2: empty"),
    (pa.table({"time": [0.0, 1.0, 2.0], "u_j2": [0.0, 1.0, float("nan")]}), r"column 'u_j2': row 3: nan is not a finite"),
    (pa.table({"time": [0.0, 1.0], "q_j2": [0.0, 10.0]}).replace_schema_metadata(
        {b"hydrohil.units": json.dumps({"time": "s", "q_j2": "deg"}).encode()}),
     r"column 'q_j2' is in deg .*read it with --column q_j2=q_j2:deg"),
    (pa.table({"time": pa.array([], pa.float64())}), "no data rows"),
])
def test_bad_parquet_named_by_column_and_row(tmp_path, table, message):
    pq.write_table(table, tmp_path / "bad.parquet")
    with pytest.raises(DatasetError, match=message):
        read_dataset(tmp_path / "bad.parquet")


def test_parquet_with_other_units_is_read_through_the_column_options(tmp_path):
    t = pa.table({"time": [0.0, 0.02, 0.04], "q_j2": [0.0, -10.0, 20.0], "u_j2": [0.0, 1.0, 2.0]})
    pq.write_table(t.replace_schema_metadata({b"hydrohil.units": json.dumps({"q_j2": "deg"}).encode()}),
                   tmp_path / "deg.parquet")
    res = import_record(tmp_path / "deg.parquet", load_robot("hydrolek"), ReadOptions(columns=("q_j2=q_j2",)))
    np.testing.assert_allclose(res.dataset["q_j2"], np.radians([0.0, -10.0, 20.0]), rtol=1e-15)
    np.testing.assert_array_equal(res.dataset["u_j2"], [0.0, 1.0, 2.0])     # taken by name, in SI


def test_not_a_parquet_file(tmp_path):
    (tmp_path / "x.parquet").write_text("time,u_j2\n0,0\n")
    with pytest.raises(DatasetError, match="x.parquet: not a readable Parquet file"):
        read_dataset(tmp_path / "x.parquet")


def test_excite_and_simulate_write_and_read_parquet_like_csv(tmp_path):
    for ext in ("csv", "parquet"):
        proc = hydrohil("excite", "--robot", "hydrolek", "--joint", "j2", "--duration", "2", "--rate", "100",
                        "--out", tmp_path / f"in.{ext}")
        assert proc.returncode == 0, proc.stderr
        proc = hydrohil("simulate", "--robot", "hydrolek", "--input", tmp_path / f"in.{ext}", "--out", tmp_path / f"out.{ext}")
        assert proc.returncode == 0, proc.stderr
    a, b = read_dataset(tmp_path / "out.csv"), read_dataset(tmp_path / "out.parquet")
    assert a.columns == b.columns and b.robot == "hydrolek"
    assert b.units["q_j2"] == "rad" and b.units["p_j2_a"] == "Pa" and b.units["u_j2"] == "V"
    np.testing.assert_allclose(a.data, b.data, rtol=1e-9, atol=1e-12)    # the CSV keeps 10 digits
    assert not np.array_equal(a.data, b.data)                           # the Parquet keeps all of them


@pytest.mark.parametrize("header", ["time,u_j2,q_j2,\n", "time,u_j2,q_j2\n", ""])
def test_rows_ending_with_a_delimiter(tmp_path, header):
    """Spreadsheet exports and some loggers end every row with a delimiter: not an extra column."""
    (tmp_path / "d.csv").write_text(header + "0,1.5,-0.3,\n0.02,2.5,-0.2,\n")
    hydrolek = load_robot("hydrolek")
    opts = ReadOptions(columns=() if header else ("time=0", "u_j2=1", "q_j2=2"))
    res = import_record(tmp_path / "d.csv", hydrolek, opts)
    np.testing.assert_array_equal(res.dataset.data, [[0, 1.5, -0.3], [0.02, 2.5, -0.2]])
    assert any("ends with a delimiter" in n for n in res.notes)
    (tmp_path / "e.csv").write_text(header + "0,1.5,-0.3,\n0.02,2.5,-0.2,7\n")    # a real fourth value
    with pytest.raises(DatasetError, match=r"row 2 \(line \d\) has 4 values"):
        import_record(tmp_path / "e.csv", hydrolek, opts)
