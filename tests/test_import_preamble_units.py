"""A log's layout around its header (sim_core/ingest/text.py): a preamble of comment lines, a header
written as a comment (numpy's savetxt), a row of units under the header (LabVIEW, DIAdem and
spreadsheet exports), and the header again further down (a second run appended). The logged values are written here, so the expected dataset comes from the
test, not from the reader."""

import json

import numpy as np
import pytest

from conftest import run_cli
from sim_core.dataset import read_dataset
from sim_core.model.spec import load_robot

N = 500


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    d = tmp_path_factory.mktemp("layout")
    run_cli("rig", "new", "boom", "--out", d / "rig", check=True)
    spec = load_robot(d / "rig")
    t = np.arange(N) * 0.02
    volts = np.round(5.0 + 0.4 * np.sin(0.7 * t), 6)    # inside the boom sensor's range, as written
    cmd = np.where(t % 4 < 2, 2.5, -2.5)
    return d, spec, t, volts, cmd


def body(t, volts, cmd, time_scale=1.0) -> str:
    return "".join(f"{ti * time_scale:.6g},{v:.6f},{u:.3f}\n" for ti, v, u in zip(t, volts, cmd))


def imported(cli, d, name, text, *columns):
    (d / name).write_text(text)
    out = d / (name + ".out.csv")
    proc = cli("import", d / name, "--robot", d / "rig", "--out", out, *columns)
    return proc, out


def sensor(spec):
    return spec.get("joints.boom.sensor.A"), spec.get("joints.boom.sensor.B")


def test_a_row_of_units_under_the_header_is_read_as_the_columns_units(cli, rig):
    d, spec, t, volts, cmd = rig
    proc, out = imported(cli, d, "units.csv", "time,pos,cmd\n[ms],[V],[V]\n" + body(t, volts, cmd, 1000.0),
                         "--column", "time=time", "--column", "q_boom=pos", "--column", "u_boom=cmd")
    assert proc.returncode == 0, proc.stderr
    assert "line 2 holds no number under the header" in proc.stdout
    ds = read_dataset(out)
    A, B = sensor(spec)
    np.testing.assert_allclose(ds.time, t, atol=1e-9)                     # milliseconds, as the row says
    np.testing.assert_allclose(ds["q_boom"], A * volts + B, atol=1e-9)    # volts of a sensed joint: its sensor's
    np.testing.assert_allclose(ds["u_boom"], cmd, atol=1e-12)
    side = json.loads((d / "units.csv.out.csv.import.json").read_text())
    assert side["columns"]["time"]["unit"] == "ms" and side["columns"]["q_boom"]["unit"] == "sensor_volts"


def test_a_unit_given_with_column_wins_over_the_row_and_a_cell_that_is_no_unit_is_said(cli, rig):
    d, spec, t, volts, cmd = rig
    text = "time,pos,cmd\ns,%,mV\n" + body(t, volts, cmd)
    proc, out = imported(cli, d, "odd.csv", text, "--column", "time=time", "--column", "q_boom=pos:sensor_volts",
                         "--column", "u_boom=cmd:V")
    assert proc.returncode == 0, proc.stderr
    assert "the row of units says" not in proc.stdout                    # both given: the row is not asked
    np.testing.assert_allclose(read_dataset(out)["u_boom"], cmd, atol=1e-12)
    proc, out = imported(cli, d, "odd2.csv", text, "--column", "time=time", "--column", "q_boom=pos",
                         "--column", "u_boom=cmd")
    assert proc.returncode == 0, proc.stderr
    assert "column q_boom (header 'pos'): the row of units says '%', no unit of" in proc.stdout
    ds = read_dataset(out)
    np.testing.assert_allclose(ds["q_boom"], volts, atol=1e-9)            # read in SI, as the note says
    np.testing.assert_allclose(ds["u_boom"], cmd * 1e-3, atol=1e-12)      # mV, as the row says


def test_a_preamble_of_comment_lines_is_skipped_and_said(cli, rig):
    d, spec, t, volts, cmd = rig
    text = "# logger v2.1, rig 4\n% 50 Hz\n\ntime;pos;cmd\n" + body(t, volts, cmd).replace(",", ";")
    proc, out = imported(cli, d, "pre.csv", text, "--column", "time=time", "--column", "q_boom=pos:sensor_volts",
                         "--column", "u_boom=cmd")
    assert proc.returncode == 0, proc.stderr
    assert "lines 1-2 start with '#': a preamble, skipped" in proc.stdout
    A, B = sensor(spec)
    np.testing.assert_allclose(read_dataset(out)["q_boom"], A * volts + B, atol=1e-9)


def test_numpys_commented_header_names_the_columns(cli, rig, tmp_path):
    d, spec, t, volts, cmd = rig
    np.savetxt(tmp_path / "np.csv", np.column_stack([t, volts, cmd]), delimiter=",", header="time,pos,cmd")
    assert (tmp_path / "np.csv").read_text().startswith("# time,pos,cmd\n")
    proc = cli("import", tmp_path / "np.csv", "--robot", d / "rig", "--out", tmp_path / "np.out.csv",
               "--column", "time=time", "--column", "q_boom=pos:sensor_volts", "--column", "u_boom=cmd")
    assert proc.returncode == 0, proc.stderr
    assert "its last line, line 1, names the columns" in proc.stdout
    np.testing.assert_allclose(read_dataset(tmp_path / "np.out.csv")["u_boom"], cmd, atol=1e-12)


def test_a_file_of_comments_only_is_refused(cli, rig, tmp_path):
    d, *_ = rig
    (tmp_path / "c.csv").write_text("# nothing logged\n# the logger stopped\n")
    proc = cli("import", tmp_path / "c.csv", "--robot", d / "rig", "--out", tmp_path / "c.out.csv", "--column",
               "time=0", "--column", "u_boom=1")
    assert proc.returncode == 2 and "nothing but comment lines (2" in proc.stderr


def test_a_header_repeated_in_the_file_is_a_second_run_and_is_refused_where_it_starts(cli, rig, tmp_path):
    d, spec, t, volts, cmd = rig
    first, second = body(t[:200], volts[:200], cmd[:200]), body(t[:100], volts[:100], cmd[:100])
    (tmp_path / "two.csv").write_text("time,pos,cmd\n" + first + "time,pos,cmd\n" + second)
    proc = cli("import", tmp_path / "two.csv", "--robot", d / "rig", "--out", tmp_path / "two.out.csv", "--column",
               "time=time", "--column", "q_boom=pos:sensor_volts", "--column", "u_boom=cmd")
    assert proc.returncode == 2
    assert "row 201 (line 202) repeats the header: a second run appended by the logger; split the file before " \
           "line 202" in proc.stderr
