"""Glitches in a measured position (sim_core/ingest/glitches.py): the rules on synthetic signals (no
simulation), then a user's rig log with wiper dropouts through ``import`` and ``diagnose``.

The synthetic motion is what a P-controlled joint does: ramps at a few speeds, holds, reversals,
white sensor noise; glitches are written into it at rows chosen here, so the expected rows and the
repaired values come from the test, not from the detector."""

import json

import numpy as np
import pytest

from conftest import run_cli
from rig_records import closed_loop_record, write_headerless
from sim_core.dataset import DatasetError, write_dataset
from sim_core.ingest import ReadOptions, read_input
from sim_core.ingest.glitches import MAX_RUN, find_glitches, repaired
from sim_core.model.spec import load_robot

SIGMA = 1e-3


def motion(n=3000, seed=0, sigma=SIGMA):
    """Ramps between random levels at up to 0.05 units per sample, held 20-80 samples, plus noise:
    the fastest clean step is about 0.05 + a few sigma."""
    rng = np.random.default_rng(seed)
    y, x = np.empty(n), 5.0
    k = 0
    while k < n:
        target = rng.uniform(2.0, 8.0)
        speed = rng.uniform(0.01, 0.05)
        while k < n and abs(target - x) > speed:
            x += np.sign(target - x) * speed
            y[k] = x
            k += 1
        hold = rng.integers(20, 80)
        y[k:k + hold] = x
        k += hold
    return y + rng.normal(0.0, sigma, n)


def rows_of(hit):
    return sorted(int(i) + 1 for i in np.flatnonzero(hit[1])) if hit else []


def test_glitches_of_one_to_three_samples_are_found_where_they_are_and_repaired():
    clean = motion()
    y = clean.copy()
    y[500] = 0.0                       # a wiper lifting: 0 V for one sample
    y[1200:1202] = 10.0                # full scale for two
    y[2000:2003] += [0.9, -0.7, 1.1]   # an interference burst of three
    hit = find_glitches(y)
    assert rows_of(hit) == [501, 1201, 1202, 2001, 2002, 2003]
    g = hit[0]
    assert (g.samples, g.runs) == (6, 3) and g.rows == [(501, 501), (1201, 1202), (2001, 2003)]
    fixed = repaired(y, hit[1])
    # a straight line between the neighbours misses the motion by at most a step of it
    assert np.max(np.abs(fixed - clean)) < 0.06
    assert np.array_equal(fixed[~hit[1]], y[~hit[1]])


def test_a_clean_motion_has_no_glitch_over_seeds_and_noise_levels():
    for seed in range(8):
        for sigma in (0.0, 1e-4, 1e-3, 5e-3):
            assert find_glitches(motion(seed=seed, sigma=sigma)) is None, (seed, sigma)


def test_an_excursion_longer_than_three_samples_is_not_a_glitch():
    y = motion()
    y[700:700 + MAX_RUN + 1] = 0.0
    assert find_glitches(y) is None
    y = motion()
    y[700:700 + MAX_RUN] = 0.0
    assert rows_of(find_glitches(y)) == [701, 702, 703]


def test_a_step_that_stays_is_not_a_glitch():
    y = motion()
    y[1500:] += 2.0                    # a sensor re-zeroed, or a real jump: it does not come back
    assert find_glitches(y) is None
    y[1500] += 0.8                     # ... even with an overshoot on its first sample
    assert find_glitches(y) is None


def test_an_excursion_the_joint_could_make_is_kept_and_one_twice_its_fastest_step_is_not():
    clean = motion(sigma=1e-4)
    fastest = np.max(np.abs(np.diff(clean)))
    k = 1060
    y = clean.copy()
    y[k] += 1.5 * fastest                # out and back at 1.5 x the record's fastest step: motion-sized
    assert find_glitches(y) is None
    y = clean.copy()
    y[k] += 3.0 * fastest                # 3 x: faster than the joint ever moves
    assert rows_of(find_glitches(y)) == [k + 1]


def test_excursions_on_many_samples_are_a_vibration_not_glitches():
    y = motion(sigma=1e-4)
    y[100:2900:20] += 0.5                # every 20th sample: 5 % of the record
    assert find_glitches(y) is None
    y = motion(sigma=1e-4)
    y[100:2900:400] += 0.5               # 7 of them: isolated
    assert len(rows_of(find_glitches(y))) == 7


def test_glitches_at_the_ends_of_the_record_take_the_one_neighbour():
    clean = motion()
    y = clean.copy()
    y[0], y[-1] = 9.0, 0.0
    hit = find_glitches(y)
    assert rows_of(hit) == [1, y.size]
    fixed = repaired(y, hit[1])
    assert fixed[0] == y[1] and fixed[-1] == y[-2]


def test_the_rule_is_unit_free():
    y = motion()
    y[[300, 1700]] = [0.0, 10.0]
    a = rows_of(find_glitches(y))
    assert a == [301, 1701]
    assert rows_of(find_glitches(0.05 * y - 0.02)) == a         # volts -> metres
    assert rows_of(find_glitches(np.round(y / 10.0 * 4095))) == a   # 12-bit counts


def test_a_still_joint_with_one_spike_a_few_tens_of_noise_sigmas_high():
    rng = np.random.default_rng(4)
    y = 4.0 + rng.normal(0.0, SIGMA, 2000)
    y[1234] += 20 * SIGMA
    assert rows_of(find_glitches(y)) == [1235]


def test_a_still_quantised_joint_with_one_dropout():
    rng = np.random.default_rng(3)
    y = np.round((4.0 + rng.normal(0.0, 1e-3, 2000)) / (10 / 4096)) * (10 / 4096)
    y[999] = 0.0
    assert rows_of(find_glitches(y)) == [1000]


# ---- the user's way: a rig log with wiper dropouts -------------------------------------------------

DROPOUTS = {700: 0.0, 1501: 0.0, 1800: 9.9976, 2222: 0.0}     # 0-based rows -> the volts logged there


@pytest.fixture(scope="module")
def dropout_log(tmp_path_factory):
    """The cylinder rig's clean closed-loop log (valve +20 %, supply -15 %, start off), once as logged
    and once with four dropouts of the potentiometer to 0 V or full scale written into it."""
    d = tmp_path_factory.mktemp("dropouts")
    run_cli("rig", "new", "cylinder", "--out", d / "rig", check=True)
    spec = load_robot(d / "rig")
    rows, _ = closed_loop_record(d / "rig", hidden=None, seed=5, start_offset=0.025,
                                 off={"joints.lift.valve.rated_flow": 1.2, "supply.pressure": 0.85})
    write_headerless(rows, d / "clean.csv")
    bad = rows.copy()
    for r, v in DROPOUTS.items():
        bad[r, 1] = v
    write_headerless(bad, d / "log.csv")
    return d, spec, rows


READ = ["--no-header", "--column", "time=0", "--column", "q_lift=1:sensor_volts", "--column", "u_lift=2"]


def test_import_repairs_the_dropouts_and_says_where(cli, dropout_log):
    d, spec, rows = dropout_log
    proc = cli("import", d / "log.csv", "--robot", d / "rig", "--out", d / "rec.csv", *READ)
    assert proc.returncode == 0, proc.stderr
    note = next(n for n in proc.stdout.splitlines() if "glitch(es)" in n)
    assert "rows 701, 1502, 1801, 2223" in note and "--glitches keep" in note
    side = json.loads((d / "rec.csv.import.json").read_text())
    g = side["columns"]["q_lift"]["glitches"]
    assert g["rows"] == [[r + 1, r + 1] for r in sorted(DROPOUTS)]
    assert side["columns"]["q_lift"]["saturation"] is None      # the full-scale dropout is a glitch, not saturation
    from sim_core.dataset import read_dataset

    q = read_dataset(d / "rec.csv")["q_lift"]
    A, B = spec.get("joints.lift.sensor.A"), spec.get("joints.lift.sensor.B")
    for r in DROPOUTS:                     # the line between the neighbours as logged (4 decimals)
        assert q[r] == pytest.approx(A * (np.round(rows[r - 1, 1], 4) + np.round(rows[r + 1, 1], 4)) / 2 + B, abs=1e-9)
    others = np.setdiff1d(np.arange(len(rows)), list(DROPOUTS))
    np.testing.assert_allclose(q[others], A * np.round(rows[others, 1], 4) + B, atol=1e-9)


def test_diagnose_on_the_log_with_dropouts_fits_to_its_noise_ceiling_and_without_the_repair_it_does_not(cli, dropout_log):
    d, _, _ = dropout_log
    verdicts = {}
    for policy in ("repair", "keep"):
        rep = d / f"rep_{policy}"
        proc = cli("diagnose", "--robot", d / "rig", d / "log.csv", *READ, "--glitches", policy, "--report", rep,
                   "--quiet")
        assert proc.returncode == 0, proc.stderr
        verdicts[policy] = json.loads((rep / "diagnosis.json").read_text())
    repair, keep = verdicts["repair"], verdicts["keep"]
    assert repair["verdict"] == "no_significant_discrepancy" and not repair["selected"]
    assert any("glitch(es)" in n for n in repair["data"]["notes"])
    # repaired, the nominal model fits the record to its noise ceiling; four dropouts left in cost the
    # angle fit more than 5 points (the velocity differentiated across them far more)
    ceiling = repair["data"]["fit_ceiling"]["lift"]
    assert repair["baseline"]["fit"]["lift"] > ceiling - 1.0
    assert keep["baseline"]["fit"]["lift"] < keep["data"]["fit_ceiling"]["lift"] - 5.0


def test_glitches_fail_names_the_column_row_and_line(cli, dropout_log):
    d, _, _ = dropout_log
    proc = cli("import", d / "log.csv", "--robot", d / "rig", "--out", d / "x.csv", *READ, "--glitches", "fail")
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert "column q_lift (column 1)" in proc.stderr and "row 701 (line 701)" in proc.stderr


def test_a_dataset_file_read_as_it_is_is_repaired_too(tmp_path, dropout_log):
    _, spec, rows = dropout_log
    A, B = spec.get("joints.lift.sensor.A"), spec.get("joints.lift.sensor.B")
    q = A * rows[:, 1] + B
    q[900] = B                                    # 0 V
    write_dataset(tmp_path / "ds.csv", {"time": rows[:, 0], "u_lift": rows[:, 2], "q_lift": q}, spec=spec)
    imp = read_input(tmp_path / "ds.csv", spec)
    assert imp.dataset["q_lift"][900] == pytest.approx((q[899] + q[901]) / 2)
    assert any("rows 901" in n for n in imp.notes)
    kept = read_input(tmp_path / "ds.csv", spec, ReadOptions(glitches="keep"))
    assert kept.dataset["q_lift"][900] == q[900]
    with pytest.raises(DatasetError, match="row 901"):
        read_input(tmp_path / "ds.csv", spec, ReadOptions(glitches="fail"))
