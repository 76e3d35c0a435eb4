"""Mains on the position sensor, seen as a steady line where mains aliases
(sim_core/identification/mains_tone.py): the rules on synthetic velocity residuals (no simulation),
each with a case that fails when the rule is deleted or inverted, and end to end: 60 Hz hum on a rig's
sensor, read by its controller and logged at 50 Hz, is said as mains at 10 Hz; a 10 Hz mode the model
lacks in the same rig's record is not."""

import math

import numpy as np
import pytest
from scipy import signal

from rig_records import closed_loop_record, diagnose_log, write_headerless
from sim_core.identification import mains_tone as mt
from sim_core.identification.residual_tests import spectrum

RATE = 50.0
N = 1200                                      # 24 s: a closed-loop record's validation window


def _tests(residual, simulated=None, rate=RATE):
    simulated = np.zeros_like(residual) if simulated is None else simulated
    return {"j": {"_spectrum": spectrum(residual, rate), "_velocity_residual": residual,
                  "_velocity_simulated": simulated}}


def _time(rate=RATE, n=N, jitter=0.0, seed=0):
    rng = np.random.default_rng(seed)
    return np.concatenate([[0.0], np.cumsum((1.0 + rng.uniform(-jitter, jitter, n - 1)) / rate)])


def _noise(seed=1, size=N, sigma=0.002):
    return np.random.default_rng(seed).normal(0.0, sigma, size)


def _found(residual, t=None, simulated=None, rate=RATE):
    t = _time(rate, residual.size) if t is None else t
    return mt.found(_tests(residual, simulated, rate), t, rate)


def test_bands_put_60_hz_mains_at_10_and_20_hz_of_a_50_hz_log_and_leave_50_hz_near_zero_out():
    rows = {(b["mains_hz"], b["harmonic"]): b for b in mt.bands(50.0, 0.0, 0.2)}
    assert set(rows) == {(60.0, 1), (60.0, 2), (60.0, 3)}         # 50, 100, 150 Hz fold to 0 Hz: not judged
    assert [rows[(60.0, k)]["alias_hz"] for k in (1, 2, 3)] == pytest.approx([10.0, 20.0, 20.0])
    lo, hi = rows[(60.0, 1)]["band_hz"]
    assert lo == pytest.approx(10.0 - 0.6 - 0.4) and hi == pytest.approx(10.0 + 0.6 + 0.4)
    # at 200 Hz the fundamentals are logged as they are; 180 Hz folds to 20 Hz
    rows = {(b["mains_hz"], b["harmonic"]): b["alias_hz"] for b in mt.bands(200.0, 0.0, 0.1)}
    assert rows[(50.0, 1)] == 50.0 and rows[(60.0, 1)] == 60.0 and rows[(60.0, 3)] == 20.0 and rows[(60.0, 2)] == 80.0
    # a wandering clock widens each band by the line's phase diffusion, the harmonics four and nine times as much
    wide = {(b["mains_hz"], b["harmonic"]): b["band_hz"] for b in mt.bands(50.0, 1.15e-3, 0.2)}
    extra = 2.0 * (2.0 * math.pi * 60.0 * 1.15e-3) ** 2 * 50.0 / (4.0 * math.pi)
    assert wide[(60.0, 1)][1] - wide[(60.0, 1)][0] == pytest.approx(2.0 * (0.6 + 0.4 + extra), abs=2e-3)
    assert (60.0, 3) not in wide                  # smeared wider than its own frequency: no line to judge


def test_a_steady_line_at_10_hz_is_said_as_60_hz_mains():
    t = _time()
    res = 0.02 * np.sin(2 * np.pi * 9.93 * t + 0.4) + _noise()
    f = _found(res, t)["j"]
    assert (f["mains_hz"], f["harmonic"]) == (60.0, 1) and f["peak_hz"] == pytest.approx(9.93, abs=0.2)
    assert f["share"] > 0.9 and f["steadiness_cv"] < 0.1 and f["contrast"] > 100


def test_a_line_sampled_by_a_wandering_clock_is_still_said():
    # 60 Hz hum sampled at instants jittered by up to 10 % of the period, cumulatively: a line smeared
    # by a phase random walk around 10 Hz
    t = _time(jitter=0.1, seed=3)
    res = 0.02 * np.sin(2 * np.pi * 59.9 * t) + _noise()
    f = _found(res, t)["j"]
    assert f["alias_hz"] == 10.0 and f["share"] > mt.SHARE_MIN


def test_a_mode_rung_by_steps_is_not_a_steady_line():
    # a 10 Hz mode, damping 0.03, rung by a step every 4 s: a line in the spectrum, not the same size throughout
    t = _time()
    kick = np.zeros(N)
    kick[::200] = 1.0
    w = 2 * np.pi * 10.0
    b, a, _ = signal.cont2discrete(([w], [1.0, 2 * 0.03 * w, w * w]), 1 / RATE)
    ring = signal.lfilter(np.ravel(b), a, kick)
    res = ring / np.std(ring) * 0.02 + _noise()
    b = next(b for b in mt.bands(RATE, 0.0, spectrum(res, RATE)[0][1]) if b["harmonic"] == 1)
    fig = mt.line(res, np.zeros(N), RATE, spectrum(res, RATE), b["band_hz"])
    assert fig["share"] > mt.SHARE_MIN and fig["contrast"] > mt.LINE_CONTRAST        # only the steadiness tells
    assert fig["steadiness_cv"] > 2 * mt.STEADY_CV
    assert _found(res, t) == {}


def test_a_steady_line_where_no_mains_falls_is_not_said():
    t = _time()
    assert _found(0.02 * np.sin(2 * np.pi * 7.0 * t) + _noise(), t) == {}
    assert _found(0.02 * np.sin(2 * np.pi * 14.5 * t) + _noise(), t) == {}


def test_a_line_that_holds_less_than_half_the_misfit_is_not_the_record_cause():
    t = _time()
    slow = np.repeat(np.random.default_rng(5).normal(0.0, 0.03, N // 25), 25)        # a coloured misfit of the motion
    res = 0.01 * np.sin(2 * np.pi * 9.93 * t) + slow + _noise()
    b = next(b for b in mt.bands(RATE, 0.0, spectrum(res, RATE)[0][1]) if b["harmonic"] == 1)
    fig = mt.line(res, np.zeros(N), RATE, spectrum(res, RATE), b["band_hz"])
    assert fig["share"] < mt.SHARE_MIN and fig["contrast"] > mt.LINE_CONTRAST and fig["steadiness_cv"] < mt.STEADY_CV
    assert _found(res, t) == {}
    assert _found(0.04 * np.sin(2 * np.pi * 9.93 * t) + slow + _noise(), t)      # the same line, larger: said


def test_a_white_residual_fills_a_wide_band_but_stands_out_nowhere():
    # a random walk on the position (the 50 Hz hum under a wandering clock) leaves a white velocity
    # residual: half its power lies in the smeared 120 Hz band (12.3-25 Hz), which holds no line
    t = _time(jitter=0.1, seed=3)
    res = _noise(sigma=0.02)
    jitter = float(np.std(np.diff(t)))
    b = next(b for b in mt.bands(RATE, jitter, spectrum(res, RATE)[0][1]) if b["harmonic"] == 2)
    fig = mt.line(res, np.zeros(N), RATE, spectrum(res, RATE), b["band_hz"])
    assert fig["share"] >= mt.SHARE_MIN and fig["steadiness_cv"] < mt.STEADY_CV and fig["contrast"] < mt.LINE_CONTRAST
    assert _found(res, t) == {}


def test_a_line_the_model_moves_at_is_the_motion_s():
    # a joint driven at 10 Hz whose gain the model misses by a third: the residual's line beside the model's own
    t = _time()
    drive = 0.06 * np.sin(2 * np.pi * 9.93 * t)
    res = drive / 3.0 + _noise()
    assert _found(res, t, simulated=drive) == {}
    assert _found(res, t, simulated=drive / 10.0)          # hum read back by the controller: the model barely moves there


def test_a_record_too_short_for_its_windows_is_not_judged():
    t = _time(n=200)
    res = 0.02 * np.sin(2 * np.pi * 9.93 * t) + _noise(size=200)
    assert _found(res, t) == {}


def _rig_log(tmp_path, **kw):
    rows, _ = closed_loop_record(tmp_path / "rig", hidden=None, seed=7, start_offset=0.02,
                                 off={"joints.swing.valve.rated_flow": 1.1, "supply.pressure": 0.9}, **kw)
    return rows


def _diagnose(cli, tmp_path, rows):
    write_headerless(rows, tmp_path / "log.csv")
    return diagnose_log(cli, tmp_path, "rep", "swing")[0]


def test_60_hz_hum_read_by_the_controller_and_logged_at_50_hz_is_said_as_mains(cli, tmp_path):
    assert cli("rig", "new", "rotary", "--out", tmp_path / "rig").returncode == 0
    # the controller reads the same hummed sensor and logs each of its 50 Hz cycles: the command carries
    # the hum's alias, and the joint, in the record and in the model alike, moves with it a little
    rows = _rig_log(tmp_path, interference=lambda t: 0.04 * math.sin(2 * math.pi * 59.95 * t + 0.7))
    d = _diagnose(cli, tmp_path, rows)
    assert d["verdict"] == "unexplained_discrepancy" and d["selected"] == [], (d["selected"], d["unexplained"])
    u = d["unexplained"]
    m = u["mains_tone"]["swing"]
    assert (m["mains_hz"], m["harmonic"]) == (60.0, 1) and m["frequency_hz"] == pytest.approx(9.95, abs=0.5)
    assert m["share"] >= mt.SHARE_MIN and m["steadiness_cv"] <= mt.STEADY_CV
    assert u["record_causes"][0].startswith("the position of swing carries a steady line")
    assert "60 Hz mains" in u["record_causes"][0]
    # the same rig, seed and loop without the hum: nothing to explain
    assert _diagnose(cli, tmp_path, _rig_log(tmp_path))["verdict"] == "no_significant_discrepancy"


def test_a_10_hz_mode_the_model_lacks_is_not_said_as_mains(cli, tmp_path):
    assert cli("rig", "new", "rotary", "--out", tmp_path / "rig").returncode == 0
    rows = _rig_log(tmp_path)
    # a bracket mode between the joint and its sensor, rung by the joint's acceleration (the sensor volts)
    w, zeta = 2 * np.pi * 10.0, 0.03
    t = np.arange(len(rows)) / 50.0
    _, x, _ = signal.lsim(signal.TransferFunction([-1.0, 0.0, 0.0], [1.0, 2 * zeta * w, w * w]), rows[:, 1] - rows[0, 1], t)
    rows[:, 1] += 4.0 * x
    d = _diagnose(cli, tmp_path, rows)
    assert d["verdict"] == "unexplained_discrepancy", d["selected"]
    u = d["unexplained"]
    assert "mains_tone" not in u and not any("steady line" in c for c in u["record_causes"])
    assert "parameter_drift" not in u          # the same rig all through: no change said either
    assert u["evidence"]["swing"]["frequency"]["peak_hz"] == pytest.approx(10.0, abs=1.0)
