"""hydrohil import on a record a logger wrote one channel per file (a sample index in one file, the
position in sensor volts in another, the valve command in a third): the files are read side by
side, row k of each being one sample. Expected values are computed here from the arrays written and
the robot.toml (tomllib), not by the reader under test."""

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from sim_core.dataset import DatasetError, read_dataset
from sim_core.ingest import ReadOptions, import_record
from sim_core.model.spec import load_robot

ROOT = Path(__file__).resolve().parent.parent
HYDROLEK_TOML = ROOT / "sim_core" / "robots" / "hydrolek" / "robot.toml"
HYDROHIL = Path(sys.executable).with_name("hydrohil")
ROWS, RATE = 400, 50.0


def hydrohil(*args):
    return subprocess.run([str(HYDROHIL), *map(str, args)], capture_output=True, text=True, timeout=300, cwd=ROOT)


@pytest.fixture
def channels(tmp_path):
    """Three one-column files of one record: sample index 1..N, sensor volts, command volts."""
    k = np.arange(1, ROWS + 1)
    volts = np.round(5.0 + 1.5 * np.sin(k / 40.0), 6)         # as written (%.6f)
    command = np.round(2.0 * np.cos(k / 25.0), 6)
    np.savetxt(tmp_path / "index.txt", k, fmt="%d")
    np.savetxt(tmp_path / "pos.txt", volts, fmt="%.6f")
    np.savetxt(tmp_path / "cmd.txt", command, fmt="%.6f")
    return tmp_path, volts, command


def test_one_channel_per_file_is_one_record(channels):
    d, volts, command = channels
    out = d / "rec.csv"
    proc = hydrohil("import", d / "index.txt", d / "pos.txt", d / "cmd.txt", "--robot", "hydrolek", "--out", out,
                    "--column", f"time=0:*{1 / RATE}", "--column", "q_j2=1:sensor_volts", "--column", "u_j2=2:V")
    assert proc.returncode == 0, proc.stderr
    with open(HYDROLEK_TOML, "rb") as fh:
        s = tomllib.load(fh)["joints"]["j2"]["sensor"]
    ds = read_dataset(out)
    assert ds.columns == ["time", "u_j2", "q_j2"]
    np.testing.assert_allclose(ds["time"], np.arange(ROWS) / RATE, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ds["q_j2"], s["A"] * volts + s["B"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(ds["u_j2"], command, rtol=0, atol=1e-9)
    side = json.loads((d / "rec.csv.import.json").read_text())
    assert side["files"] == [str(d / n) for n in ("index.txt", "pos.txt", "cmd.txt")]
    assert side["columns"]["u_j2"]["source"] == f"column 2: {d / 'cmd.txt'}'s column 0"
    assert "cmd.txt's column 0" in proc.stdout


def test_a_single_file_keeps_its_report(tmp_path):
    np.savetxt(tmp_path / "log.csv", np.c_[np.arange(50) * 0.02, np.zeros(50)], fmt="%.4f", delimiter=",")
    res = import_record(tmp_path / "log.csv", load_robot("hydrolek"), ReadOptions(columns=("time=0", "u_j2=1")))
    side = res.to_dict()
    assert side["source"] == str(tmp_path / "log.csv") and side["files"] == [side["source"]]
    assert side["columns"]["u_j2"]["source"] == "column 1"


def test_files_of_different_lengths_are_refused_naming_both(channels):
    d, _, command = channels
    np.savetxt(d / "cmd.txt", command[:-3], fmt="%.6f")
    out = d / "rec.csv"
    proc = hydrohil("import", d / "pos.txt", d / "cmd.txt", "--robot", "hydrolek", "--out", out, "--rate", RATE,
                    "--column", "q_j2=0:sensor_volts", "--column", "u_j2=1")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert f"{d / 'pos.txt'} {ROWS}, {d / 'cmd.txt'} {ROWS - 3}" in proc.stderr, proc.stderr
    assert not out.exists()


def test_a_bad_cell_names_its_own_file_and_line(channels):
    d, _, command = channels
    lines = [f"{v:.6f}" for v in command]
    lines[123] = "n/a"
    (d / "cmd.txt").write_text("\n".join(lines) + "\n")
    proc = hydrohil("import", d / "pos.txt", d / "cmd.txt", "--robot", "hydrolek", "--out", d / "rec.csv", "--rate",
                    RATE, "--column", "q_j2=0:sensor_volts", "--column", "u_j2=1")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert f"{d / 'cmd.txt'}: column u_j2" in proc.stderr and "row 124 (line 124): 'n/a' is not a number" in proc.stderr


def test_columns_are_numbered_on_across_files(channels):
    d, _, _ = channels
    spec = load_robot("hydrolek")
    with pytest.raises(DatasetError, match=r"column index 2 is out of range: the files have 2 column\(s\) together"):
        import_record([d / "pos.txt", d / "cmd.txt"], spec, ReadOptions(columns=("q_j2=0:sensor_volts", "u_j2=2"),
                                                                       rate=RATE))
    res = import_record([d / "cmd.txt", d / "pos.txt"], spec, ReadOptions(columns=("q_j2=1:sensor_volts", "u_j2=0"),
                                                                          rate=RATE))
    np.testing.assert_allclose(res.dataset["u_j2"], np.loadtxt(d / "cmd.txt"), atol=1e-12)


def test_header_names_across_files(tmp_path):
    t = np.arange(60) * 20.0
    np.savetxt(tmp_path / "a.csv", np.c_[t, np.full(60, 0.1)], fmt="%.3f", delimiter=",", header="t_ms,value",
               comments="")
    np.savetxt(tmp_path / "b.csv", np.c_[np.full(60, 0.2), np.full(60, 1.5)], fmt="%.3f", delimiter=",",
               header="value,u_j2", comments="")
    spec = load_robot("hydrolek")
    files = [tmp_path / "a.csv", tmp_path / "b.csv"]
    with pytest.raises(DatasetError, match=r"header 'value' is in more than one file .*by its index \(1, 2\)"):
        import_record(files, spec, ReadOptions(columns=("time=t_ms:ms", "q_j2=value")))
    with pytest.raises(DatasetError, match=r"no column 'pos' in the files' headers \(.*a.csv: t_ms, value; .*b.csv: "
                                           r"value, u_j2\)"):
        import_record(files, spec, ReadOptions(columns=("time=t_ms:ms", "q_j2=pos")))
    res = import_record(files, spec, ReadOptions(columns=("time=t_ms:ms", "q_j2=2")))
    np.testing.assert_allclose(res.dataset["q_j2"], 0.2)
    np.testing.assert_allclose(res.dataset["u_j2"], 1.5)      # a header named like a dataset column, in b.csv
    assert res.to_dict()["columns"]["u_j2"]["source"] == f"header 'u_j2' in {tmp_path / 'b.csv'}"
