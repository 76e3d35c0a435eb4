"""The pieces of the identification: metrics, residual tests, signatures, the candidate bank, the
parameter file, and diagnose's handling of bad input (clear errors naming the column or option)."""

import math

import numpy as np
import pytest

from sim_core.effects import EFFECTS, diagnosable
from sim_core.identification.candidates import bank
from sim_core.identification.metrics import fit_ceiling, noise_std, nrmse_fit, savgol_window, velocity
from sim_core.params_file import overrides
from sim_core.identification.residual_tests import correlation_band, cross_correlation, ljung_box
from sim_core.identification.signatures import joint_signatures


def test_nrmse_fit_is_matlabs_compare_fit():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    assert nrmse_fit(y, y) == 100.0
    assert nrmse_fit(y, np.full(4, y.mean())) == pytest.approx(0.0)
    yhat = y + np.array([0.5, -0.5, 0.5, -0.5])
    # 100 (1 - ||y - yhat|| / ||y - mean||) = 100 (1 - 1 / sqrt(5))
    assert nrmse_fit(y, yhat) == pytest.approx(100 * (1 - 1 / math.sqrt(5)))
    assert nrmse_fit(y, -y) < 0


@pytest.mark.parametrize("n, dt, window", [(7200, 0.005, None), (3000, 0.02, None), (500, 0.001, 21), (9, 0.02, 9)])
def test_velocity_is_scipys_savitzky_golay_derivative(n, dt, window):
    """The smoothed velocity every fit compares is scipy's order-2 Savitzky-Golay derivative (mode
    'interp': the end samples from the parabola fitted to the end window), ends included."""
    from scipy.signal import savgol_filter

    rng = np.random.default_rng(n)
    t = np.arange(n) * dt
    y = np.sin(3 * t) + 0.2 * t ** 2 + np.cumsum(rng.normal(0, 1e-3, n))
    w = window or savgol_window(1.0 / dt)
    ref = savgol_filter(y, w, 2, deriv=1, delta=dt)
    np.testing.assert_allclose(velocity(y, dt, window), ref, rtol=0, atol=1e-9 * np.max(np.abs(ref)))


def test_noise_floor_estimates():
    rng = np.random.default_rng(1)
    t = np.linspace(0, 60, 12001)
    smooth = 0.3 * np.sin(0.5 * t) + 0.1 * np.clip(np.sin(0.13 * t) * 4, -1, 1)
    y = smooth + rng.normal(0, 4e-4, t.size)
    assert noise_std(y) == pytest.approx(4e-4, rel=0.1)
    # the ceiling is the fit of the noise-free signal itself
    assert fit_ceiling(y, 4e-4) == pytest.approx(nrmse_fit(y, smooth), abs=0.05)


@pytest.mark.parametrize("quanta_per_sigma", [0.2, 0.5, 0.8, 1.0, 1.5])
def test_the_noise_of_a_quantised_reading_is_not_held_to_whole_quanta(quanta_per_sigma):
    """A 16-bit reading's second differences sit on its quantum's lattice, where a plain median of
    them moves in whole quanta (10-17 % off at 0.5-1.5 quanta per sigma); the estimate is the noise
    plus the quantisation's own (q^2 / 12) within the median's sampling spread, at every ratio. The
    CSV's ten significant digits put the lattice's values 1e-10 apart, not on it exactly."""
    rng = np.random.default_rng(int(10 * quanta_per_sigma))
    t = np.arange(20000) / 50.0
    sigma = 3e-4
    q = quanta_per_sigma * sigma
    y = np.round((0.3 * np.sin(1.2 * t) + rng.normal(0, sigma, t.size)) / q) * q
    y = np.array([float(f"{v:.10g}") for v in y])
    assert noise_std(y) == pytest.approx(math.sqrt(sigma ** 2 + q ** 2 / 12), rel=0.04)


def test_the_grouped_median_is_the_plain_one_off_a_lattice_and_interpolates_on_one():
    from sim_core.identification.metrics import grouped_median

    x = np.random.default_rng(5).normal(size=1001)
    assert grouped_median(x) == np.median(x)
    # 0, 1, 1, 1, 2: the median value 1 stands for [0.5, 1.5]; one sample below, three in it
    assert grouped_median(np.array([0.0, 1.0, 1.0, 1.0, 2.0])) == pytest.approx(0.5 + (2.5 - 1) / 3)
    # absolute values: the bin at 0 is [0, 0.5]
    assert grouped_median(np.array([0.0, 0.0, 0.0, 1.0]), floor=0.0) == pytest.approx(0.5 * 2 / 3)


def test_whiteness_and_independence():
    rng = np.random.default_rng(2)
    e = rng.normal(size=5000)
    q, p = ljung_box(e, 20)
    assert p > 0.001
    coloured = np.convolve(e, np.ones(20) / 20, mode="same")
    assert ljung_box(coloured, 20)[1] < 1e-6
    u = rng.normal(size=5000)
    lags, r = cross_correlation(np.roll(u, 7) + 0.1 * e, u, 20)
    assert lags[np.argmax(r)] == 7                       # the residual follows u by 7 samples
    assert abs(r[lags == 0][0]) < correlation_band(e, u, 20)


def test_signatures_name_a_deadband_and_a_sensor_offset():
    """Synthetic joint: speed = k * dead_zone(u, 1 V); the model has no deadband."""
    rate = 200.0
    rng = np.random.default_rng(3)
    levels = rng.choice([-5, -3, -1.5, 1.5, 3, 5, 0], size=120)
    u = np.repeat(levels, 100).astype(float)
    t = np.arange(u.size) / rate
    dz = np.sign(u) * np.maximum(np.abs(u) - 1.0, 0)
    y = np.cumsum(0.02 * dz) / rate
    yhat = np.cumsum(0.02 * u * 0.8) / rate
    sig = joint_signatures(t, y + rng.normal(0, 1e-4, t.size), yhat, u, 1e-4, rate)
    assert sig["deadband_t"] > 4
    assert sig["guesses"]["deadband"]["width"] == pytest.approx(1.0, rel=0.3)
    off = joint_signatures(t, yhat + 0.02 + rng.normal(0, 1e-4, t.size), yhat, u, 1e-4, rate)
    assert off["sensor_offset"] == pytest.approx(0.02, abs=1e-3)
    assert off["sensor_R2"] > 0.99


def test_bank_offers_every_applicable_effect(plants):
    spec = plants("hydrolek").spec
    names = {c.effect for c in bank(spec, ["j2"])}
    assert names == set(diagnosable()) and "stribeck_friction" not in names  # simulation-only: no fit hints
    rotary = {c.effect for c in bank(plants("harvester").spec, ["swing"]) if c.joint == "swing"}
    assert "area_ratio" not in rotary and "leakage" in rotary
    # an effect the nominal model has is refitted from its value: its null is that value
    h = plants("harvester").spec
    db = next(c for c in bank(h, ["boom"]) if c.effect == "deadband")
    assert db.existing and db.free[0].null == pytest.approx(1.2)
    for c in bank(spec, ["j2"]):
        s = c.prepare(spec)                     # every candidate switches on with valid parameters
        assert any(e.name == c.effect and e.joint == c.joint for e in s.effects)
        for point in c.grid:
            for fp, v in zip(c.free, point):
                assert fp.lower <= v <= fp.upper


def test_a_nominal_valve_offset_beyond_the_search_span_is_refitted_around_its_value(plants):
    spec = plants("hydrolek").spec.copy()
    spec.enable_effect("valve_offset", "j2", offset=-3.0)      # 2x the 1.5 V default bound of a +-10 V valve
    c = next(c for c in bank(spec, ["j2"]) if c.effect == "valve_offset")
    fp = c.free[0]
    assert c.existing and fp.null == pytest.approx(-3.0) and fp.lower <= -3.0 <= fp.upper
    assert all(fp.lower <= v <= fp.upper for (v,) in c.grid) and min(abs(v + 3.0) for (v,) in c.grid) < 0.5


def test_parameter_file_round_trip(plants):
    base = plants("harvester").spec
    spec = base.copy()
    spec.set("joints.boom.valve.rated_flow", 2.6e-3)
    spec.enable_effect("deadband", "boom", width=1.7)
    spec.enable_effect("delay", "stick", delay=0.02)
    spec.disable_effect("line_dynamics", "swing")
    data = overrides(spec)
    assert data["parameters"] == {"joints.boom.valve.rated_flow": 2.6e-3}
    again = base.copy()
    again.apply_overrides(data)
    assert again.parameters() == spec.parameters()
    assert {(e.name, e.joint, tuple(sorted(e.params.items()))) for e in again.effects} == \
        {(e.name, e.joint, tuple(sorted(e.params.items()))) for e in spec.effects}


def _write(path, header, rows):
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n")


@pytest.mark.parametrize("header,rows,needle", [
    (["t", "u_j2", "q_j2"], [[i * 0.01, 1.0, 0.0] for i in range(400)], "missing column 'time'"),
    (["time", "u_j2"], [[i * 0.01, 1.0] for i in range(400)], "no measured angle column"),
    (["time", "u_j2", "q_j2", "q_j9"], [[i * 0.01, 1.0, 0.0, 0.0] for i in range(400)], "q_j9"),
    (["time", "u_j2", "q_j2"], [[i * 0.01, 12.0, 0.0] for i in range(400)], "u_j2"),
    (["time", "u_j2", "q_j2"], [[i * 0.01, 0.0, 0.0] for i in range(400)], "no joint is commanded"),
    (["time", "u_j3", "q_j2"], [[i * 0.01, 1.0, 0.0] for i in range(400)], "q_j3"),
    (["time", "u_j2", "q_j2"], [[i * 0.01, 1.0, 0.0] for i in range(20)], "rows"),
    (["time", "u_j2", "q_j2"], [[0.001 * i, 1.0, 0.0] for i in range(400)], "lasts"),
])
def test_bad_records_give_clear_errors(cli, tmp_path, header, rows, needle):
    csv = tmp_path / "bad.csv"
    _write(csv, header, rows)
    proc = cli("diagnose", "--robot", "hydrolek", csv, "--report", tmp_path / "rep", "--quiet")
    assert proc.returncode == 2
    assert "hydrohil diagnose: error:" in proc.stderr and needle in proc.stderr
    assert "Traceback" not in proc.stderr


def test_bad_options_give_clear_errors(cli, tmp_path):
    csv = tmp_path / "ok.csv"
    _write(csv, ["time", "u_j2", "q_j2"], [[i * 0.01, 1.0, -0.3 + 0.001 * i] for i in range(400)])   # a joint that moves
    proc = cli("diagnose", "--robot", "hydrolek", csv, "--report", tmp_path / "r", "--effects", "warp_drive")
    assert proc.returncode == 2 and "warp_drive" in proc.stderr
    proc = cli("diagnose", "--robot", "hydrolek", tmp_path / "missing.csv", "--report", tmp_path / "r")
    assert proc.returncode == 2 and "no such file" in proc.stderr
    proc = cli("diagnose", "--robot", "hydrolek", csv, "--validation", tmp_path / "missing.csv", "--report", tmp_path / "r")
    assert proc.returncode == 2 and "missing.csv" in proc.stderr


def test_reported_numbers_keep_six_significant_digits():
    """Candidate parameters are reported to 6 significant digits: a leakage coefficient of order
    1e-13 m^3/(s Pa) is not rounded to 0, and large numbers are not padded with false digits."""
    from sim_core.identification.diagnosis import _num

    assert _num(3.21e-13) == pytest.approx(3.21e-13, rel=1e-6, abs=0)
    assert _num(1234567.891) == 1234570.0
    assert _num(float("nan")) is None and _num(None) is None


def test_a_named_parameter_is_reported_at_its_null_only_where_the_fit_it_comes_from_left_it_there():
    """A leak whose round fit put the piston leak on its lower bound (none) and the rest to tank: once
    the part to tank is held at none and the leak refitted, the piston leak carries it, off that
    bound. The value reported is the final refit's, so is the bound it is judged on: the round's is
    stale (a named leak of 0 is no finding)."""
    from sim_core.identification import output_error as oe
    from sim_core.identification.candidates import Candidate
    from sim_core.identification.decision import Evaluation
    from sim_core.identification.diagnosis import _absent, _bound_of
    from sim_core.identification.parameters import FreeParameter

    key = "effects.leakage.swing.internal"
    fp = FreeParameter(key, 1e-15, 3e-10, log=True, null=0.0)      # the bank's piston leak
    ev = Evaluation(Candidate("leakage", "swing", [fp]), {key: 0.0}, {}, {}, 1.0, {}, bounds={key: "lower"})
    final = oe.FitResult([fp], {key: 7.7e-14}, 1.0)
    assert _bound_of(key, final, ev) is None
    assert _absent(fp, 7.7e-14, _bound_of(key, final, ev)) == 7.7e-14
    # no final refit, or one that did not fit it: the round's bound, and a value on its null is the null
    assert _bound_of(key, None, ev) == "lower"
    assert _bound_of(key, oe.FitResult([], {}, 1.0), ev) == "lower"
    assert _absent(fp, 1e-15, "lower") == 0.0
    # where the final refit itself stops it there, it is reported there too
    assert _absent(fp, 1e-15, _bound_of(key, oe.FitResult([fp], {key: 1e-15}, 1.0), ev)) == 0.0
