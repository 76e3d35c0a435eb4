"""A time column that is a wrapping tick counter (sim_core/ingest/counter_wrap.py): the rule on
arrays (no simulation), then a PLC-style log whose 16-bit millisecond counter wraps three times,
through ``import``. The counter's values are made here from a known time, so the expected time
comes from the test."""

import numpy as np
import pytest

from conftest import run_cli
from sim_core.dataset import read_dataset
from sim_core.ingest.counter_wrap import unwrapped


def ticks(seconds=200.0, rate=50.0, start_ms=12345, bits=16, jitter_ms=0.0, seed=0):
    t_ms = np.arange(int(seconds * rate)) * 1000.0 / rate + start_ms
    t_ms = t_ms + np.random.default_rng(seed).uniform(-jitter_ms, jitter_ms, t_ms.size)
    return t_ms, np.mod(np.round(t_ms), 2 ** bits)


@pytest.mark.parametrize("bits", [8, 16, 24])
def test_a_wrapping_counter_is_unwrapped_at_each_wrap(bits):
    true, counter = ticks(seconds=400.0 if bits == 24 else 200.0, start_ms=2 ** bits - 100 if bits == 24 else 12345,
                          bits=bits, jitter_ms=2.0)
    out, wraps = unwrapped(counter)
    assert wraps is not None and wraps.bits == bits
    np.testing.assert_array_equal(out - out[0], np.round(true) - np.round(true[0]))
    expected_rows = [int(i) + 2 for i in np.flatnonzero(np.diff(counter) < 0)]
    assert wraps.rows == expected_rows and len(expected_rows) >= 1


def test_a_signed_counter_wraps_from_its_top_to_its_bottom():
    true = np.arange(5000) * 20.0                       # ms
    counter = (true + 2 ** 15) % 2 ** 16 - 2 ** 15      # int16: 32767 -> -32768
    out, wraps = unwrapped(counter)
    assert wraps is not None and wraps.bits == 16
    np.testing.assert_array_equal(out - out[0], true)


def test_a_drop_that_is_no_wrap_is_left_for_the_time_check():
    _, counter = ticks()
    restarted = np.concatenate([np.arange(3000) * 20.0, np.arange(3000) * 20.0])   # a second run appended
    assert unwrapped(restarted)[1] is None
    set_back = counter.copy()
    set_back[4000:] = np.mod(set_back[4000:] - 500.0, 2 ** 16)   # a clock set back half a second
    out, wraps = unwrapped(set_back)
    assert wraps is not None and 4001 not in wraps.rows             # its wraps undone, not the set-back
    assert out[4000] < out[3999] and np.all(np.delete(np.diff(out), 3999) > 0)
    assert unwrapped(np.arange(100.0))[1] is None      # no drop at all


def test_import_reads_a_plc_log_whose_millisecond_counter_wraps(cli, tmp_path):
    run_cli("rig", "new", "boom", "--out", tmp_path / "rig", check=True)
    true_ms, counter = ticks()
    t = (true_ms - true_ms[0]) / 1000.0
    v = np.round(5.0 + 0.4 * np.sin(0.7 * t), 6)
    u = np.where(t % 4 < 2, 2.5, -2.5)
    (tmp_path / "plc.csv").write_text("".join(f"{int(c)},{a:.6f},{b:.3f}\n" for c, a, b in zip(counter, v, u)))
    read = ["--no-header", "--column", "time=0:ms", "--column", "q_boom=1:sensor_volts", "--column", "u_boom=2"]
    proc = cli("import", tmp_path / "plc.csv", "--robot", tmp_path / "rig", "--out", tmp_path / "rec.csv", *read)
    assert proc.returncode == 0, proc.stderr
    rows = [int(i) + 2 for i in np.flatnonzero(np.diff(counter) < 0)]
    assert f"a 16-bit counter that starts again after 65535 ms (3 time(s), rows {', '.join(map(str, rows))})" in proc.stdout
    np.testing.assert_allclose(read_dataset(tmp_path / "rec.csv").time, t, atol=1e-9)
    # the same log with a second run appended is still refused, naming the row
    (tmp_path / "two.csv").write_text((tmp_path / "plc.csv").read_text() * 2)
    proc = cli("import", tmp_path / "two.csv", "--robot", tmp_path / "rig", "--out", tmp_path / "two_rec.csv", *read)
    assert proc.returncode == 2 and f"row {counter.size + 1}" in proc.stderr and "time goes backwards" in proc.stderr
