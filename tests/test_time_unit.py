"""A time column read in the wrong unit (ingest/timegrid.py, identification/record.py): a logger's
milliseconds read as seconds turn a 50 Hz record into a 0.05 Hz one that lasts hours, and each
simulation of it would too. The import notes it with the unit that reads it right; fit and diagnose
refuse a grid coarser than SLOW_RATE_HZ at once, naming the column and that unit."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sim_core.dataset import Dataset, DatasetError
from sim_core.identification.record import record_from_dataset
from sim_core.identification.record import MIN_DURATION
from sim_core.ingest.timegrid import FAST_RATE_HZ, SLOW_RATE_HZ, short_hint, unit_hint
from sim_core.model.spec import load_robot

ROOT = Path(__file__).resolve().parent.parent
LOG = ROOT / "tests" / "data" / "import" / "boom_50hz_noheader.csv"      # time in ms, 50 Hz, 1000 rows
HYDROHIL = Path(sys.executable).with_name("hydrohil")
COLUMNS = ["--no-header", "--column", "q_j2=1:sensor_volts", "--column", "u_j2=2:V"]


def hydrohil(*args, timeout=120):
    return subprocess.run([str(HYDROHIL), *map(str, args)], capture_output=True, text=True, timeout=timeout, cwd=ROOT)


@pytest.fixture(scope="module")
def seconds_read_as_ms(tmp_path_factory):
    """The 50 Hz log imported with its millisecond time column taken as seconds (the default unit)."""
    out = tmp_path_factory.mktemp("ms") / "rec.csv"
    proc = hydrohil("import", LOG, "--robot", "hydrolek", "--out", out, "--column", "time=0", *COLUMNS)
    return proc, out


def test_import_notes_the_coarse_grid_and_the_unit_that_reads_it(seconds_read_as_ms):
    proc, out = seconds_read_as_ms
    assert proc.returncode == 0, proc.stderr
    notes = json.loads(Path(f"{out}.import.json").read_text())["notes"]
    (note,) = [n for n in notes if f"below the {SLOW_RATE_HZ:g} Hz" in n]
    assert "--column time=SOURCE:ms" in note and note in proc.stdout
    rate = float(note.split("ms, ")[1].split(" Hz")[0])        # what the hint says the record's rate is
    assert abs(rate - 50.0) < 0.5


@pytest.mark.parametrize("command", ["diagnose", "fit"])
def test_fit_and_diagnose_refuse_it_at_once_naming_the_column_and_the_unit(seconds_read_as_ms, tmp_path, command):
    _, rec = seconds_read_as_ms
    extra = ["--report", tmp_path / "rep"] if command == "diagnose" else ["--out", tmp_path / "p.toml"]
    proc = hydrohil(command, rec, "--robot", "hydrolek", *extra, timeout=60)    # without the check: hours
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "column 'time'" in proc.stderr and "--column time=SOURCE:ms" in proc.stderr
    assert f"at least {SLOW_RATE_HZ:g} Hz" in proc.stderr


def test_the_hinted_unit_reads_the_log_at_its_rate(tmp_path):
    out = tmp_path / "rec.csv"
    proc = hydrohil("import", LOG, "--robot", "hydrolek", "--out", out, "--column", "time=0:ms", *COLUMNS)
    assert proc.returncode == 0, proc.stderr
    side = json.loads(Path(f"{out}.import.json").read_text())
    assert abs(side["rate_hz"] - 50.0) < 0.5
    assert not any("below the" in n for n in side["notes"])


def test_microseconds_get_the_scale_that_reads_them(tmp_path):
    raw = np.loadtxt(LOG, delimiter=",")
    raw[:, 0] *= 1e3                                   # the same log in microseconds
    log = tmp_path / "us.csv"
    np.savetxt(log, raw, delimiter=",", fmt="%.6f")
    hint = unit_hint(float(np.median(np.diff(raw[:, 0]))))
    assert ":*1e-6" in hint
    unit = hint.split("time=SOURCE")[1].split(" ")[0]
    out = tmp_path / "rec.csv"
    proc = hydrohil("import", log, "--robot", "hydrolek", "--out", out, "--column", f"time=0{unit}", *COLUMNS)
    assert proc.returncode == 0, proc.stderr
    assert abs(json.loads(Path(f"{out}.import.json").read_text())["rate_hz"] - 50.0) < 0.5


def _record(rate_hz: float):
    """The HydroLek shoulder commanded with a square wave, its reading a ramp, 60 samples."""
    n = 60
    t = np.arange(n) / rate_hz
    u = np.where((np.arange(n) // 10) % 2, 3.0, -3.0)
    q = 0.3 + 0.4 * np.linspace(0.0, 1.0, n) + np.random.default_rng(0).normal(0.0, 1e-4, n)
    return record_from_dataset(Dataset(["time", "u_j2", "q_j2"], np.column_stack([t, u, q])), load_robot("hydrolek"),
                               source="rec.csv")


def test_the_limit_is_the_median_sample_rate():
    assert _record(1.1 * SLOW_RATE_HZ).rate == pytest.approx(1.1 * SLOW_RATE_HZ)
    with pytest.raises(DatasetError) as err:
        _record(0.9 * SLOW_RATE_HZ)
    assert str(err.value).startswith("rec.csv: column 'time': a sample every")


def test_a_rate_given_too_low_is_noted(tmp_path):
    raw = np.loadtxt(LOG, delimiter=",")
    log = tmp_path / "no_time.csv"
    np.savetxt(log, raw[:, 1:3], delimiter=",", fmt="%.4f")
    out = tmp_path / "rec.csv"
    proc = hydrohil("import", log, "--robot", "hydrolek", "--out", out, "--no-header", "--rate", 0.5 * SLOW_RATE_HZ,
                    "--column", "q_j2=0:sensor_volts", "--column", "u_j2=1:V")
    assert proc.returncode == 0, proc.stderr
    assert "check --rate" in proc.stdout


def test_a_record_too_short_gets_the_minutes_that_read_it_long_enough():
    minutes = short_hint(0.02 / 60.0, 20.0 / 60.0, MIN_DURATION)              # 20 s at 50 Hz, counted in minutes
    assert ":*60 (a sample every 20 ms, 50 Hz, 20 s)" in minutes and ":*3600" not in minutes     # hours: 180 kHz
    hours = short_hint(0.02 / 3600.0, 600.0 / 3600.0, MIN_DURATION)           # 10 min at 50 Hz, in hours
    assert ":*3600 (a sample every 20 ms, 50 Hz, 600 s)" in hours and ":*60 " in hours   # minutes fit too
    assert short_hint(0.02, 1.0, MIN_DURATION) == ""                           # a short 50 Hz record is short
    assert ":*60" not in short_hint(1.0 / (1.1 * FAST_RATE_HZ) / 60.0, 1.0, MIN_DURATION)   # no logger runs that fast
    assert short_hint(0.02 / 3600.0, 0.5 * MIN_DURATION / 3600.0, MIN_DURATION) == ""     # short in any unit


def test_diagnose_refuses_minutes_read_as_seconds_with_the_unit(tmp_path):
    raw = np.loadtxt(LOG, delimiter=",")
    raw[:, 0] = (raw[:, 0] - raw[0, 0]) * 1e-3 / 60.0          # the 20 s log's time in minutes
    log = tmp_path / "minutes.csv"
    np.savetxt(log, raw, delimiter=",", fmt="%.8f")
    proc = hydrohil("diagnose", "--robot", "hydrolek", log, "--column", "time=0", *COLUMNS, "--report", tmp_path / "r")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "column 'time': the record lasts" in proc.stderr and "--column time=SOURCE:*60" in proc.stderr

