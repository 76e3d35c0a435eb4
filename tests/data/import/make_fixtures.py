"""Writes the log-file fixtures of tests/test_import.py the way real rig loggers write them; the
constants below are what the tests check the reader against. Run from anywhere:
``python tests/data/import/make_fixtures.py`` (deterministic: the files do not change).

HydroLek joint j2 (sensor: angle = 0.5921 rad/V * v - 2.842 rad) stands for a boom; the slide rig
(tests/data/import/slide) for a linear axis (position = 0.05 m/V * v - 0.02 m).
"""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

# boom_50hz_noheader.csv: t [ms], sensor volts, command [V], p_a [bar], p_b [bar]; no header
RATE = 50.0
ROWS_50HZ = 1000
JITTER = 0.03                 # timestamps t_k = k T + e_k, e_k uniform in +-JITTER * T
A_J2, B_J2 = 0.5921, -2.842   # the j2 sensor model of hydrolek/robot.toml (the tests read it themselves)

# boom_deg_semicolon.csv: 2 preamble lines, header, ';' with decimal commas, angle [deg], command [mV]
PREAMBLE = 2
ROWS_DEG = 500
RATE_DEG = 100.0

# counts_no_time.csv: no header, no time: sample index, position 16-bit counts of 0..10 V,
# p_a 12-bit counts of 0..250 bar (saturates), p_b 12-bit counts (does not), command as a -1..1 fraction
RATE_COUNTS = 200.0
ROWS_COUNTS = 800
COUNTS_FULL_BAR = 250.0
SATURATED_RUNS = [(300, 311), (520, 526)]       # rows (from 1, inclusive) where p_a exceeds 250 bar

# repeated_and_gap.csv: a dataset-like header, 50 Hz; rows REPEATED repeat the previous row; the
# samples after row GAP_AFTER are missing for GAP_MISSING periods
REPEATED = [101, 201, 301]    # data rows (from 1) that repeat the row before them
GAP_AFTER, GAP_MISSING = 400, 5
ROWS_REPEATED = 600

# backwards.csv: no header; data row BACK_ROW's time is 0.05 s before the previous row's
BACK_ROW = 57

# text_cell.csv: header; data row TEXT_ROW has TEXT_CELL in the 'pa' column (an overload marker)
TEXT_ROW, TEXT_CELL = 123, "OVL"

# nan_cell.csv: no header; data row EMPTY_ROW has an empty command cell
EMPTY_ROW = 42

# slide_mm.csv: the slide rig; header time_ms,pos_mm,pos_V,cmd; position 0.05..0.35 m
ROWS_SLIDE = 400
A_SLIDE, B_SLIDE = 0.05, -0.02


def boom_angle(t):
    return -0.3 + 0.35 * np.sin(2 * math.pi * 0.2 * t)


def p_controller(q, t):
    ref = -0.3 + 0.3 * np.sign(np.sin(2 * math.pi * 0.1 * t))
    return np.clip(25.0 * (ref - q), -10.0, 10.0)


def write_boom_50hz(rng):
    k = np.arange(ROWS_50HZ)
    T = 1.0 / RATE
    t = k * T + rng.uniform(-JITTER * T, JITTER * T, k.size) + 12.5     # the logger's clock started earlier
    q = boom_angle(t)
    v = (q - B_J2) / A_J2
    u = p_controller(q, t)
    pa = 90.0 + 30.0 * np.sin(t) + rng.normal(0, 0.5, k.size)
    pb = 70.0 - 20.0 * np.sin(t) + rng.normal(0, 0.5, k.size)
    with open(HERE / "boom_50hz_noheader.csv", "w", newline="\r\n") as fh:    # a Windows logger
        for row in zip(1e3 * t, v, u, pa, pb):
            fh.write("{:.3f},{:.4f},{:.3f},{:.2f},{:.2f}\n".format(*row))


def write_boom_deg(rng):
    t = np.arange(ROWS_DEG) / RATE_DEG
    q = boom_angle(t)
    u = p_controller(q, t)
    with open(HERE / "boom_deg_semicolon.csv", "w") as fh:
        fh.write("Logger HX-200 firmware 1.4\n# started 2026-11-03 10:00:00\n")
        fh.write("Zeit [s];Winkel [deg];Ventil [mV]\n")
        for a, b, c in zip(t, np.degrees(q), 1e3 * u):
            fh.write(f"{a:.2f};{b:.3f};{c:.1f}\n".replace(".", ","))


def write_counts(rng):
    i = np.arange(1, ROWS_COUNTS + 1)
    t = (i - 1) / RATE_COUNTS
    q = boom_angle(t)
    v = (q - B_J2) / A_J2
    pos = np.round(v / 10.0 * 65535).astype(int)
    pa_bar = 150.0 + 20.0 * np.sin(t)
    for a, b in SATURATED_RUNS:                 # pressure spikes beyond the transducer's range
        pa_bar[a - 1:b] = 262.0 + rng.uniform(0, 5, b - a + 1)
    pa = np.clip(np.round(pa_bar / COUNTS_FULL_BAR * 4095), 0, 4095).astype(int)
    pb = np.round((60.0 + 10 * np.cos(t)) / COUNTS_FULL_BAR * 4095).astype(int)
    frac = p_controller(q, t) / 10.0
    with open(HERE / "counts_no_time.csv", "w") as fh:
        for row in zip(i, pos, pa, pb, frac):
            fh.write("{}\t{}\t{}\t{}\t{:.4f}\n".format(*row))


def write_repeated(rng):
    T = 1.0 / RATE
    rows, k = [], 0
    while len(rows) < ROWS_REPEATED:
        r = len(rows) + 1
        if r in REPEATED:
            rows.append(rows[-1])
            continue
        if r == GAP_AFTER + 1:
            k += GAP_MISSING
        t = k * T
        q = boom_angle(t)
        rows.append((t, float(p_controller(q, t)), q))
        k += 1
    with open(HERE / "repeated_and_gap.csv", "w") as fh:
        fh.write("time,u_j2,q_j2\n")
        for row in rows:
            fh.write("{:.4f},{:.3f},{:.5f}\n".format(*row))


def write_backwards():
    t = np.arange(100) / RATE
    t[BACK_ROW - 1:] -= 0.05 + 1.0 / RATE
    q = boom_angle(t)
    with open(HERE / "backwards.csv", "w") as fh:
        for a, b, c in zip(t, (q - B_J2) / A_J2, p_controller(q, t)):
            fh.write(f"{a:.3f},{b:.4f},{c:.3f}\n")


def write_text_cell():
    t = np.arange(200) / RATE
    with open(HERE / "text_cell.csv", "w") as fh:
        fh.write("t,pos,cmd,pa,pb\n")
        for r, a in enumerate(t, start=1):
            q = boom_angle(a)
            pa = TEXT_CELL if r == TEXT_ROW else f"{90 + 10 * math.sin(a):.2f}"
            fh.write(f"{a:.3f},{(q - B_J2) / A_J2:.4f},{float(p_controller(q, a)):.3f},{pa},{70.0:.2f}\n")


def write_nan_cell():
    t = np.arange(100) / RATE
    with open(HERE / "nan_cell.csv", "w") as fh:
        for r, a in enumerate(t, start=1):
            q = boom_angle(a)
            u = "" if r == EMPTY_ROW else f"{float(p_controller(q, a)):.3f}"
            fh.write(f"{a:.3f},{(q - B_J2) / A_J2:.4f},{u}\n")


def write_slide():
    t = np.arange(ROWS_SLIDE) / RATE
    x = 0.2 + 0.15 * np.sin(2 * math.pi * 0.25 * t)
    u = np.clip(40.0 * (0.2 - x), -10, 10)
    with open(HERE / "slide_mm.csv", "w") as fh:
        fh.write("time_ms,pos_mm,pos_V,cmd\n")
        for a, b, c, d in zip(1e3 * t, 1e3 * x, (x - B_SLIDE) / A_SLIDE, u):
            fh.write(f"{a:.1f},{b:.3f},{c:.5f},{d:.3f}\n")


def main():
    rng = np.random.default_rng(20261103)
    write_boom_50hz(rng)
    write_boom_deg(rng)
    write_counts(rng)
    write_repeated(rng)
    write_backwards()
    write_text_cell()
    write_nan_cell()
    write_slide()
    (HERE / "empty.csv").write_bytes(b"")
    with gzip.GzipFile(HERE / "boom_50hz.csv.gz", "wb", mtime=0) as fh:     # a compressed log: not text
        fh.write((HERE / "boom_50hz_noheader.csv").read_bytes())


if __name__ == "__main__":
    main()
