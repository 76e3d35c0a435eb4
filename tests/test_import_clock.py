"""Time columns written as clock readings (a date and time, or a time of day), as LabVIEW, PLC and
spreadsheet loggers write them: import, diagnose's reading options and the clock module's rules.
Expected times are computed here from the datetimes written, not by the reader under test."""

import datetime as dt
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from sim_core.dataset import DatasetError
from sim_core.ingest import ReadOptions, import_record
from sim_core.ingest import clock
from sim_core.model.spec import load_robot

HYDROHIL = Path(sys.executable).with_name("hydrohil")
START = dt.datetime(2026, 11, 26, 12, 3, 45, 120000)


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    from conftest import run_cli

    d = tmp_path_factory.mktemp("clock") / "rig"
    run_cli("rig", "new", "cylinder", "--out", d, check=True)
    return d


def write_log(path: Path, stamps: list[str], header: str | None = None, delimiter: str = ","):
    """A log whose time column holds ``stamps``: sensor volts and a command beside them."""
    n = len(stamps)
    v = 2.0 + np.sin(np.arange(n) * 0.02)
    u = np.round(np.cos(np.arange(n) * 0.02), 3)
    lines = ([header] if header else []) + [f"{s}{delimiter}{a:.4f}{delimiter}{b:.3f}" for s, a, b in zip(stamps, v, u)]
    path.write_text("\n".join(lines) + "\n")
    return v, u


def offsets(n: int, period: float = 0.02, jitter: float = 0.0, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.round(np.arange(n) * period + rng.uniform(-jitter, jitter, n) * period, 6)


def imported(path, rig, *extra, columns=("time=0", "q_lift=1:sensor_volts", "u_lift=2")):
    opts = ReadOptions(columns=list(columns), no_header="--no-header" in extra)
    return import_record(path, load_robot(rig), opts)


def test_date_and_time_and_time_of_day_read_as_seconds_from_the_first_row(tmp_path, rig):
    t = offsets(500, jitter=0.05)
    stamps = [START + dt.timedelta(seconds=float(s)) for s in t]
    full = [s.isoformat(sep=" ", timespec="microseconds") for s in stamps]
    iso_t = [s.isoformat(sep="T", timespec="milliseconds") + "Z" for s in stamps]
    day = [s.strftime("%H:%M:%S.%f") for s in stamps]
    for name, cells, kind in (("full", full, "date and time"), ("iso", iso_t, "date and time"),
                              ("day", day, "time of day")):
        v, u = write_log(tmp_path / f"{name}.csv", cells)
        res = import_record(tmp_path / f"{name}.csv", load_robot(rig),
                            ReadOptions(columns=["time=0", "q_lift=1:sensor_volts", "u_lift=2"], no_header=True))
        ds = res.dataset
        expect = np.array([(s - stamps[0]).total_seconds() for s in stamps])
        if name == "iso":                               # written to the millisecond
            expect = np.array([(s.replace(microsecond=s.microsecond // 1000 * 1000)
                                - stamps[0].replace(microsecond=stamps[0].microsecond // 1000 * 1000)).total_seconds()
                               for s in stamps])
        assert np.max(np.abs(ds["time"] - expect)) < 1e-9, name     # microseconds kept exactly
        assert np.allclose(ds["u_lift"], u)
        assert any(f"clock readings ({kind})" in n for n in res.notes), res.notes


def test_a_time_of_day_past_midnight_counts_on(tmp_path, rig):
    base = dt.datetime(2026, 11, 26, 23, 59, 58)
    stamps = [base + dt.timedelta(seconds=0.02 * i) for i in range(400)]       # 8 s, midnight at 2 s
    write_log(tmp_path / "night.csv", [s.strftime("%H:%M:%S.%f")[:-3] for s in stamps])
    res = imported(tmp_path / "night.csv", rig, "--no-header")
    t = res.dataset["time"]
    assert np.allclose(np.diff(t), 0.02, atol=1e-9) and t[-1] == pytest.approx(7.98, abs=1e-9)
    assert any("passed midnight 1 time" in n for n in res.notes), res.notes
    assert clock.past_midnight(np.array([86399.0, 0.5, 1.0]))[1] == 1
    assert clock.past_midnight(np.array([10.0, 9.0, 11.0]))[1] == 0          # a jitter back is not a day


def test_zones_are_read_in_utc(tmp_path, rig):
    cells = ["2026-11-26T12:00:00.000+01:00", "2026-11-26T11:00:00.020Z", "2026-11-26T12:00:00.040+01:00",
             "2026-11-26T11:00:00.060+00:00"]
    write_log(tmp_path / "zones.csv", cells)
    t = imported(tmp_path / "zones.csv", rig, "--no-header").dataset["time"]
    assert np.allclose(t, [0.0, 0.02, 0.04, 0.06], atol=1e-9)


def test_without_no_header_a_first_row_of_clock_readings_is_data_and_a_header_still_works(tmp_path, rig):
    t = offsets(200)
    cells = [(START + dt.timedelta(seconds=float(s))).strftime("%H:%M:%S.%f") for s in t]
    write_log(tmp_path / "plain.csv", cells)
    res = imported(tmp_path / "plain.csv", rig)
    assert len(res.dataset) == 200                      # the first row is not a header
    write_log(tmp_path / "named.csv", cells, header="Time,Position,Command")
    res = imported(tmp_path / "named.csv", rig, columns=("time=Time", "q_lift=Position:sensor_volts",
                                                        "u_lift=Command"))
    assert len(res.dataset) == 200 and np.allclose(res.dataset["time"], t, atol=1e-9)


def test_bad_clock_cells_and_units_are_named(tmp_path, rig):
    cells = [(START + dt.timedelta(seconds=0.02 * i)).strftime("%H:%M:%S.%f") for i in range(50)]
    cells[17] = "0.34"
    write_log(tmp_path / "mixed.csv", cells)
    with pytest.raises(DatasetError, match=r"row 18 \(line 18\): '0.34' is not a time of day"):
        imported(tmp_path / "mixed.csv", rig, "--no-header")
    cells[17] = "12:61:00.000"
    write_log(tmp_path / "mixed.csv", cells)
    with pytest.raises(DatasetError, match="row 18"):
        imported(tmp_path / "mixed.csv", rig, "--no-header")
    write_log(tmp_path / "ok.csv", cells[:17])
    with pytest.raises(DatasetError, match="clock readings .* drop the unit 'ms'"):
        imported(tmp_path / "ok.csv", rig, "--no-header", columns=("time=0:ms", "q_lift=1:sensor_volts", "u_lift=2"))
    # a clock reading in a column that is not the time column is not a number there
    with pytest.raises(DatasetError, match="is not a number"):
        imported(tmp_path / "ok.csv", rig, "--no-header", columns=("time=1", "q_lift=0:sensor_volts", "u_lift=2"))


def test_a_date_and_time_split_by_blanks_gets_a_hint_and_its_time_of_day_reads(tmp_path, rig):
    stamps = [START + dt.timedelta(seconds=0.02 * i) for i in range(100)]
    write_log(tmp_path / "blanks.txt", [s.isoformat(sep=" ", timespec="milliseconds") for s in stamps], delimiter=" ")
    with pytest.raises(DatasetError, match="but a date: .* two columns"):
        imported(tmp_path / "blanks.txt", rig, "--no-header", columns=("time=0", "q_lift=2:sensor_volts", "u_lift=3"))
    t = imported(tmp_path / "blanks.txt", rig, "--no-header",
                 columns=("time=1", "q_lift=2:sensor_volts", "u_lift=3")).dataset["time"]
    assert np.allclose(t, 0.02 * np.arange(100), atol=1e-9)


def test_diagnose_reads_a_clock_column_directly(tmp_path, rig):
    """The reading options of diagnose take the same log (no import step): refused or read, never a
    traceback; here the short log is read and refused only for not moving enough to diagnose, or
    diagnosed."""
    import subprocess

    cells = [(START + dt.timedelta(seconds=0.02 * i)).strftime("%H:%M:%S.%f")[:-3] for i in range(300)]
    write_log(tmp_path / "log.csv", cells)
    p = subprocess.run([str(HYDROHIL), "simulate", "--robot", str(rig), "--input", str(tmp_path / "log.csv"),
                        "--no-header", "--column", "time=0", "--column", "u_lift=2",
                        "--out", str(tmp_path / "sim.csv")], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    header = (tmp_path / "sim.csv").read_text().splitlines()[0].split(",")
    rows = np.loadtxt(tmp_path / "sim.csv", delimiter=",", skiprows=1)
    assert np.allclose(rows[:, header.index("time")], 0.02 * np.arange(300), atol=1e-9)


def test_clock_rules():
    assert clock.kind("12:03:45.120") == "time of day" and clock.kind("9:05:00") == "time of day"
    assert clock.kind("2026-11-26 12:03:45,5") == "date and time" and clock.kind("2026-11-26T12:03") == "date and time"
    for bad in ("25:00:00", "12:60:00", "12:00:61", "2026-13-01 00:00:00", "2026-11-26", "0.5", "", "12:00"):
        assert clock.kind(bad) is None, bad
        assert clock.seconds(bad) is None, bad
    assert clock.seconds("12:03:45.1234567") == pytest.approx(43425.1234567, abs=1e-9)       # digits kept
    assert clock.seconds("1970-01-02 00:00:01.25") == 86401.25
    first = clock.whole_seconds("2026-11-26 12:03:45.000001")
    assert clock.seconds("2026-11-26 12:03:45.000001", first) == pytest.approx(1e-6, abs=1e-12)
    assert json.dumps(clock.seconds("00:00:00")) == "0.0"


def test_parquet_timestamps_times_of_day_and_durations(tmp_path, rig):
    import pyarrow as pa
    import pyarrow.parquet as pq

    n = 200
    steps = np.round(offsets(n, jitter=0.05) * 1e6).astype(np.int64)
    steps -= steps[0]                                                      # microseconds after the first row
    v = 2.0 + np.sin(np.arange(n) * 0.02)
    u = np.cos(np.arange(n) * 0.02)
    night = (86399 * 1_000_000 + steps) % (86400 * 1_000_000)             # a time of day across midnight
    columns = {
        "stamp": pa.array(np.datetime64("2026-11-26T12:03:45.120") + steps.astype("timedelta64[us]")),
        "zoned": pa.array(np.datetime64("2026-11-26T12:03:45.120") + steps.astype("timedelta64[us]"),
                          type=pa.timestamp("us", tz="Europe/Helsinki")),
        "day": pa.array(night, type=pa.time64("us")),
        "elapsed": pa.array(steps.astype("timedelta64[us]")),
    }
    pq.write_table(pa.table({**columns, "pos": v, "cmd": u}), tmp_path / "log.parquet")
    for name in columns:
        res = imported(tmp_path / "log.parquet", rig, columns=(f"time={name}", "q_lift=pos:sensor_volts", "u_lift=cmd"))
        assert np.max(np.abs(res.dataset["time"] - steps * 1e-6)) < 1e-9, name
        assert any("clock readings" in n for n in res.notes), (name, res.notes)
    with pytest.raises(DatasetError, match="drop the unit"):
        imported(tmp_path / "log.parquet", rig, columns=("time=stamp:ms", "q_lift=pos:sensor_volts", "u_lift=cmd"))
    with pytest.raises(DatasetError, match="holds timestamp"):                 # not as a measured column
        imported(tmp_path / "log.parquet", rig, columns=("time=elapsed", "q_lift=stamp:sensor_volts", "u_lift=cmd"))
