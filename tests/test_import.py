"""hydrohil import and the reading options of simulate/fit/diagnose, on log files written the way rig
loggers write them (tests/data/import, made by make_fixtures.py, whose constants the checks use),
through the hydrohil console script and the Python API. Expected values are computed here from the
raw files (csv module) and the robot.toml (tomllib), not by the reader under test."""

import csv
import importlib.util
import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from sim_core.dataset import DatasetError, read_dataset
from sim_core.identification.record import load_record
from sim_core.ingest import ReadOptions, import_record, read_input
from sim_core.model.spec import load_robot

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data" / "import"
HYDROLEK_TOML = ROOT / "sim_core" / "robots" / "hydrolek" / "robot.toml"
SLIDE_TOML = DATA / "slide" / "robot.toml"
HYDROHIL = Path(sys.executable).with_name("hydrohil")

_spec = importlib.util.spec_from_file_location("make_fixtures", DATA / "make_fixtures.py")
FX = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(FX)

BOOM = ["--column", "time=0:ms", "--column", "q_j2=1:sensor_volts", "--column", "u_j2=2:V",
        "--column", "p_j2_a=3:bar", "--column", "p_j2_b=4:bar"]


def hydrohil(*args, timeout=600):
    return subprocess.run([str(HYDROHIL), *map(str, args)], capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def sensor_model(toml_path, joint):
    """(A, B) of a joint's sensor, read from the robot.toml itself."""
    with open(toml_path, "rb") as fh:
        s = tomllib.load(fh)["joints"][joint]["sensor"]
    return s["A"], s["B"]


def raw_rows(name, delimiter=",", skip=0, decimal="."):
    with open(DATA / name, newline="") as fh:
        rows = list(csv.reader(fh, delimiter=delimiter))[skip:]
    return np.array([[float(c.replace(decimal, ".")) for c in r] for r in rows if r])


@pytest.fixture(scope="module")
def hydrolek():
    return load_robot("hydrolek")


def test_headerless_50hz_log_in_ms_sensor_volts_and_bar(tmp_path):
    out = tmp_path / "boom.csv"
    proc = hydrohil("import", DATA / "boom_50hz_noheader.csv", "--robot", "hydrolek", "--out", out, *BOOM)
    assert proc.returncode == 0, proc.stderr
    raw = raw_rows("boom_50hz_noheader.csv")
    ds = read_dataset(out)
    assert ds.columns == ["time", "u_j2", "q_j2", "p_j2_a", "p_j2_b"]
    assert len(ds) == FX.ROWS_50HZ
    A, B = sensor_model(HYDROLEK_TOML, "j2")
    np.testing.assert_allclose(ds["q_j2"], A * raw[:, 1] + B, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ds["p_j2_a"], raw[:, 3] * 1e5, rtol=1e-9)
    np.testing.assert_allclose(ds["time"], (raw[:, 0] - raw[0, 0]) / 1e3, rtol=0, atol=1e-9)
    side = json.loads((tmp_path / "boom.csv.import.json").read_text())
    q = side["columns"]["q_j2"]
    assert (q["source"], q["unit"], q["si_unit"]) == ("column 1", "sensor_volts", "rad")
    assert q["conversion"]["scale"] == A and q["conversion"]["offset"] == B
    g = side["time_grid"]
    # timestamps k T + e, e uniform in +-a: intervals spread with std sqrt(2/3) a, at most 2 a
    a_pct = 100 * FX.JITTER
    assert abs(g["jitter_rms_pct"] - math.sqrt(2 / 3) * a_pct) < 0.15 * math.sqrt(2 / 3) * a_pct
    assert 1.6 * a_pct < g["jitter_max_pct"] <= 2 * a_pct + 0.05
    assert abs(g["rate_hz"] - FX.RATE) < 0.002 * FX.RATE
    assert g["gaps"] == 0 and g["repeated"] == 0
    assert abs(g["start_s"] - 12.5) < 2 * FX.JITTER / FX.RATE
    assert "jitter" in proc.stdout and "sensor volts" in proc.stdout


def test_preamble_semicolons_decimal_commas_degrees_and_millivolts(hydrolek):
    opts = ReadOptions(columns=("time=Zeit [s]", "q_j2=Winkel [deg]:deg", "u_j2=Ventil [mV]:mV"), skip_rows=FX.PREAMBLE)
    res = import_record(DATA / "boom_deg_semicolon.csv", hydrolek, opts)
    raw = raw_rows("boom_deg_semicolon.csv", delimiter=";", skip=FX.PREAMBLE + 1, decimal=",")
    ds = res.dataset
    assert len(ds) == FX.ROWS_DEG and abs(res.grid.rate_hz - FX.RATE_DEG) < 1e-6
    np.testing.assert_allclose(ds["q_j2"], raw[:, 1] * math.pi / 180, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ds["u_j2"], raw[:, 2] / 1e3, rtol=0, atol=1e-12)
    assert any("decimal separator: comma" in n for n in res.notes)
    # without skipping the preamble, its first line is taken for the header
    with pytest.raises(DatasetError, match=r"no column 'Zeit \[s\]' in the header"):
        import_record(DATA / "boom_deg_semicolon.csv", hydrolek, ReadOptions(columns=opts.columns))


COUNTS = ["--column", f"q_j2=1:*{FX.A_J2 * 10 / 65535!r}{FX.B_J2:+}",
          "--column", f"p_j2_a=2:*{FX.COUNTS_FULL_BAR * 1e5 / 4095!r}",
          "--column", f"p_j2_b=3:*{FX.COUNTS_FULL_BAR * 1e5 / 4095!r}", "--column", "u_j2=4:*10"]


def test_counts_without_time_column_need_rate_and_saturation_is_masked(tmp_path):
    out = tmp_path / "counts.csv"
    proc = hydrohil("import", DATA / "counts_no_time.csv", "--robot", "hydrolek", "--out", out, *COUNTS)
    assert proc.returncode == 2 and "no time column" in proc.stderr and "--rate" in proc.stderr
    proc = hydrohil("import", DATA / "counts_no_time.csv", "--robot", "hydrolek", "--out", out, "--rate",
                    FX.RATE_COUNTS, *COUNTS)
    assert proc.returncode == 0, proc.stderr
    raw = raw_rows("counts_no_time.csv", delimiter="\t")
    ds = read_dataset(out)
    np.testing.assert_allclose(ds["time"], np.arange(FX.ROWS_COUNTS) / FX.RATE_COUNTS, rtol=0, atol=1e-12)
    A, B = sensor_model(HYDROLEK_TOML, "j2")
    np.testing.assert_allclose(ds["q_j2"], A * raw[:, 1] * 10 / 65535 + B, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ds["u_j2"], raw[:, 4] * 10, rtol=0, atol=1e-12)
    side = json.loads((tmp_path / "counts.csv.import.json").read_text())
    sat = side["columns"]["p_j2_a"]["saturation"]
    runs = FX.SATURATED_RUNS
    assert sat["samples"] == sum(b - a + 1 for a, b in runs) and sat["runs"] == len(runs)
    assert sat["rows"] == [list(r) for r in runs] and sat["full_scale"] == [0, 4095]
    assert side["masked"]["p_j2_a"] == [[a - 1, b - 1] for a, b in runs]
    assert side["columns"]["p_j2_b"]["saturation"] is None     # 12-bit counts that never reach full scale
    assert "p_j2_b" not in side["masked"]
    assert "SATURATED" in proc.stdout
    proc = hydrohil("import", DATA / "counts_no_time.csv", "--robot", "hydrolek", "--out", tmp_path / "f.csv",
                    "--rate", FX.RATE_COUNTS, "--saturation", "fail", *COUNTS)
    assert proc.returncode == 2
    assert f"column p_j2_a (column 2): row {runs[0][0]} (line {runs[0][0]})" in proc.stderr, proc.stderr
    assert not (tmp_path / "f.csv").exists()


def test_repeated_timestamps_dropped_and_gap_reported(tmp_path):
    out = tmp_path / "rep.parquet"
    proc = hydrohil("import", DATA / "repeated_and_gap.csv", "--robot", "hydrolek", "--out", out)
    assert proc.returncode == 0, proc.stderr
    raw = raw_rows("repeated_and_gap.csv", skip=1)
    kept = np.delete(raw, [r - 1 for r in FX.REPEATED], axis=0)
    ds = read_dataset(out)
    assert len(ds) == FX.ROWS_REPEATED - len(FX.REPEATED)
    np.testing.assert_array_equal(ds["q_j2"], kept[:, 2])
    assert np.all(np.diff(ds.time) > 0)
    g = json.loads(Path(str(out) + ".import.json").read_text())["time_grid"]
    assert g["repeated"] == len(FX.REPEATED) and g["repeated_rows"] == FX.REPEATED
    assert g["gaps"] == 1 and g["missing_samples"] == FX.GAP_MISSING
    assert abs(g["largest_gap_s"] - (FX.GAP_MISSING + 1) / FX.RATE) < 1e-9
    assert "repeat the previous timestamp and were dropped" in proc.stdout


def test_time_going_backwards_names_the_row(tmp_path):
    proc = hydrohil("import", DATA / "backwards.csv", "--robot", "hydrolek", "--out", tmp_path / "o.csv",
                    "--column", "time=0", "--column", "q_j2=1:sensor_volts", "--column", "u_j2=2")
    assert proc.returncode == 2
    assert "backwards.csv" in proc.stderr and f"row {FX.BACK_ROW} (line {FX.BACK_ROW})" in proc.stderr
    assert "time goes backwards" in proc.stderr and "Traceback" not in proc.stderr
    assert "second run" not in proc.stderr          # a step back, not back to the start
    assert not (tmp_path / "o.csv").exists()


def test_a_second_run_appended_to_the_log_is_named_with_where_to_split(tmp_path):
    t = np.arange(300) * 0.02
    rows = np.column_stack([np.concatenate([t, t[:200]]), np.full(500, 4.0), np.full(500, 1.0)])
    np.savetxt(tmp_path / "two_runs.csv", rows, delimiter=",", fmt="%.4f")
    proc = hydrohil("import", tmp_path / "two_runs.csv", "--robot", "hydrolek", "--out", tmp_path / "o.csv",
                    "--no-header", "--column", "time=0", "--column", "q_j2=1:sensor_volts", "--column", "u_j2=2")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "row 301 (line 301): time goes backwards" in proc.stderr
    assert "a second run seems to start there" in proc.stderr and "split the file before row 301" in proc.stderr


BAD = [
    ("text_cell", "text_cell.csv", ["--column", "time=t", "--column", "q_j2=pos:sensor_volts", "--column", "p_j2_a=pa:bar"],
     f"text_cell.csv: column p_j2_a (header 'pa'): row {FX.TEXT_ROW} (line {FX.TEXT_ROW + 1}): '{FX.TEXT_CELL}' is not a number"),
    ("empty_cell", "nan_cell.csv", ["--column", "time=0", "--column", "u_j2=2"],
     f"nan_cell.csv: column u_j2 (column 2): row {FX.EMPTY_ROW} (line {FX.EMPTY_ROW}): is empty"),
    ("empty_file", "empty.csv", ["--column", "time=0"], "empty.csv: empty file"),
    ("not_text", "boom_50hz.csv.gz", ["--column", "time=0"], "boom_50hz.csv.gz: not a text file"),
    ("no_such_column", "text_cell.csv", ["--column", "time=t", "--column", "q_j2=position"],
     "text_cell.csv: --column 'q_j2=position': no column 'position' in the header; columns: t, pos, cmd, pa, pb"),
    ("index_out_of_range", "boom_50hz_noheader.csv", ["--column", "time=0:ms", "--column", "u_j2=7"],
     "column index 7 is out of range: the file has 5 column(s), 0..4"),
    ("name_without_header", "boom_50hz_noheader.csv", ["--column", "time=t"], "the file has no header row"),
    ("unit_misfit", "boom_50hz_noheader.csv", ["--column", "time=0:ms", "--column", "u_j2=2:bar"],
     "unit 'bar' does not fit a valve command"),
    ("not_a_unit", "boom_50hz_noheader.csv", ["--column", "time=0:ms", "--column", "u_j2=2:volts"],
     "'volts' is not a unit"),
    ("not_a_dataset_column", "boom_50hz_noheader.csv", ["--column", "time=0:ms", "--column", "q_j9=1"],
     "'q_j9' is not a dataset column of hydrolek"),
    ("sensor_volts_unsensed", "boom_50hz_noheader.csv", ["--column", "time=0:ms", "--column", "q_j6=1:sensor_volts"],
     "this joint has none"),
    ("command_unit_wrong", "boom_50hz_noheader.csv", ["--column", "time=0:ms", "--column", "u_j2=2:*1000"],
     "column u_j2 (column 2): row 1 (line 1): 7505 V is outside the joint's command range [-10, 10] V; check the unit"),
    ("command_range_named", "boom_50hz_noheader.csv", ["--column", "time=0:ms", "--column", "u_j2=2:*1000"],
     "widen joints.j2.cfp.command_range in the robot's spec"),
    ("time_and_rate", "boom_50hz_noheader.csv", ["--column", "time=0:ms", "--column", "u_j2=2", "--rate", "50"],
     "both a time column and --rate"),
    ("only_time", "boom_50hz_noheader.csv", ["--column", "time=0:ms"], "only a time column is mapped"),
    ("no_such_file", "missing.csv", ["--column", "time=0"], "missing.csv: no such file"),
]


@pytest.mark.parametrize("name,raw,args,message", BAD, ids=[b[0] for b in BAD])
def test_bad_input_exits_non_zero_naming_file_column_row(tmp_path, name, raw, args, message):
    out = tmp_path / "o.csv"
    proc = hydrohil("import", DATA / raw, "--robot", "hydrolek", "--out", out, *args)
    assert proc.returncode == 2, proc.stdout
    assert message in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists()


def test_prismatic_joint_positions_in_metres(tmp_path):
    slide = load_robot(SLIDE_TOML)
    raw = raw_rows("slide_mm.csv", skip=1)
    by_mm = import_record(DATA / "slide_mm.csv", slide,
                          ReadOptions(columns=("time=time_ms:ms", "q_lift=pos_mm:mm", "u_lift=cmd")))
    A, B = sensor_model(SLIDE_TOML, "lift")
    by_volts = import_record(DATA / "slide_mm.csv", slide,
                             ReadOptions(columns=("time=time_ms:ms", "q_lift=pos_V:sensor_volts", "u_lift=cmd")))
    np.testing.assert_allclose(by_mm.dataset["q_lift"], raw[:, 1] / 1e3, rtol=0, atol=1e-12)
    np.testing.assert_allclose(by_volts.dataset["q_lift"], A * raw[:, 2] + B, rtol=0, atol=1e-12)
    # both columns were logged from the same position: mm to 1 um, volts to 10 uV (0.5 um)
    np.testing.assert_allclose(by_volts.dataset["q_lift"], by_mm.dataset["q_lift"], rtol=0, atol=2e-6)
    assert by_mm.to_dict()["columns"]["q_lift"]["si_unit"] == "m"
    with pytest.raises(DatasetError, match="does not fit the position of a prismatic joint"):
        import_record(DATA / "slide_mm.csv", slide, ReadOptions(columns=("time=time_ms:ms", "q_lift=pos_mm:deg")))
    with pytest.raises(DatasetError, match="does not fit the angle of a revolute joint"):
        import_record(DATA / "slide_mm.csv", load_robot("hydrolek"), ReadOptions(columns=("time=time_ms:ms", "q_j2=pos_mm:mm")))
    proc = hydrohil("import", DATA / "slide_mm.csv", "--robot", SLIDE_TOML, "--out", tmp_path / "s.parquet",
                    "--column", "time=time_ms:ms", "--column", "q_lift=pos_mm:mm", "--column", "u_lift=cmd")
    assert proc.returncode == 0, proc.stderr
    ds = read_dataset(tmp_path / "s.parquet")
    assert ds.units == {"time": "s", "u_lift": "V", "q_lift": "m"} and ds.robot == "slide"


def test_header_is_detected_and_no_header_forces_data(hydrolek):
    res = import_record(DATA / "boom_50hz_noheader.csv", hydrolek, ReadOptions(columns=("time=0:ms", "u_j2=2")))
    assert len(res.dataset) == FX.ROWS_50HZ                 # the first line is data: no row lost
    assert any("no header row" in n for n in res.notes)
    with pytest.raises(DatasetError, match=r"column time \(column 0\): row 1 \(line 3\): 'Zeit \[s\]' is not a number"):
        import_record(DATA / "boom_deg_semicolon.csv", hydrolek,
                      ReadOptions(columns=("time=0", "q_j2=1:deg"), no_header=True, skip_rows=FX.PREAMBLE))


def test_last_line_cut_short_by_the_logger_is_dropped(tmp_path, hydrolek):
    text = (DATA / "boom_50hz_noheader.csv").read_bytes()
    cut = tmp_path / "cut.csv"
    cut.write_bytes(text[: text.rstrip().rfind(b",")])      # the last line loses its last value
    res = import_record(cut, hydrolek, ReadOptions(columns=("time=0:ms", "u_j2=2")))
    assert len(res.dataset) == FX.ROWS_50HZ - 1
    assert any(f"row {FX.ROWS_50HZ} (line {FX.ROWS_50HZ}), the last, has 4 of 5 values" in n for n in res.notes)


def test_simulate_reads_a_log_file_like_its_import(tmp_path):
    imported = tmp_path / "imp.csv"
    assert hydrohil("import", DATA / "boom_50hz_noheader.csv", "--robot", "hydrolek", "--out", imported,
                    *BOOM).returncode == 0
    direct, via = tmp_path / "direct.csv", tmp_path / "via.csv"
    proc = hydrohil("simulate", "--robot", "hydrolek", "--input", DATA / "boom_50hz_noheader.csv", "--out", direct, *BOOM)
    assert proc.returncode == 0, proc.stderr
    assert "jitter" in proc.stderr                     # the reading notes are shown
    assert hydrohil("simulate", "--robot", "hydrolek", "--input", imported, "--out", via).returncode == 0
    a, b = read_dataset(direct), read_dataset(via)
    assert a.columns == b.columns
    np.testing.assert_allclose(a.data, b.data, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(a.time, read_dataset(imported).time, rtol=0, atol=1e-12)   # the jittered grid is kept


def test_record_loader_takes_the_reading_options(tmp_path, hydrolek):
    opts = ReadOptions(columns=tuple(BOOM[1::2]))
    rec = load_record(DATA / "boom_50hz_noheader.csv", hydrolek, options=opts)
    res = read_input(DATA / "boom_50hz_noheader.csv", hydrolek, opts)
    ds = res.dataset
    np.testing.assert_array_equal(rec.angles["j2"], ds["q_j2"])
    np.testing.assert_array_equal(rec.u("j2"), ds["u_j2"])
    np.testing.assert_array_equal(rec.pressures["j2"][0], ds["p_j2_a"])
    assert rec.time[0] == 0.0 and abs(rec.dt - 1 / FX.RATE) < 0.002 / FX.RATE
    assert any("jitter" in n for n in rec.notes)
    # no reading option: a dataset file under the dataset's strict rules (the log file is refused)
    with pytest.raises(DatasetError):
        load_record(DATA / "boom_50hz_noheader.csv", hydrolek)


def test_fit_on_a_log_file_equals_fit_on_its_import(tmp_path):
    imported = tmp_path / "imp.csv"
    assert hydrohil("import", DATA / "boom_50hz_noheader.csv", "--robot", "hydrolek", "--out", imported,
                    *BOOM).returncode == 0
    common = ["--robot", "hydrolek", "--max-simulations", "4", "--json"]
    direct = hydrohil("fit", DATA / "boom_50hz_noheader.csv", "--out", tmp_path / "a.toml", *common, *BOOM)
    assert direct.returncode == 0, direct.stderr
    via = hydrohil("fit", imported, "--out", tmp_path / "b.toml", *common)
    assert via.returncode == 0, via.stderr
    pa, pb = (json.loads(p.stdout)["parameters"] for p in (direct, via))
    assert pa.keys() == pb.keys()
    for k in pa:
        assert pa[k]["value"] == pytest.approx(pb[k]["value"], rel=1e-6)


@pytest.mark.parametrize("command", ["fit", "diagnose"])
def test_fit_and_diagnose_report_reading_errors_by_row(tmp_path, command):
    extra = ["--report", tmp_path / "rep"] if command == "diagnose" else ["--out", tmp_path / "p.toml"]
    proc = hydrohil(command, DATA / "backwards.csv", "--robot", "hydrolek", *extra, "--column", "time=0",
                    "--column", "q_j2=1:sensor_volts", "--column", "u_j2=2")
    assert proc.returncode == 2
    assert f"backwards.csv: column time (column 0): row {FX.BACK_ROW} (line {FX.BACK_ROW})" in proc.stderr, proc.stderr
