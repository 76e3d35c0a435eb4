"""Dataset I/O: write and read a 1 h, 1 kHz HydroLek record (the 27 columns `hydrohil simulate` writes
for hydrolek, synthetic values of the same magnitudes) as CSV and as Parquet: seconds and file size,
and the ratio to the CSV reader and writer as they were before the fast path (the Python csv-module
loop and np.savetxt, kept below as the reference), measured in the same run.

    .venv/bin/python benchmarks/bench_io.py [--duration S] [--no-reference] [--json]
"""

import argparse
import csv
import io
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from sim_core.dataset import Dataset, read_dataset, write_dataset
from sim_core.model.spec import load_robot


def hydrolek_record(duration: float, rate: float = 1000.0, seed: int = 0) -> dict[str, np.ndarray]:
    """Columns of a simulated HydroLek record: commands in V (PRBS levels), angles in rad (smooth, with
    the sensor's noise and its 16-bit quantisation, as `simulate` writes them), chamber pressures in
    Pa (about 4-10 MPa, every digit significant)."""
    spec = load_robot("hydrolek")
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate)) + 1
    t = np.arange(n) / rate
    cols = {"time": t}
    for j in spec.joint_names:
        levels = rng.choice([-5.0, -2.5, 0.0, 2.5, 5.0], size=n // 500 + 1)
        cols[f"u_{j}"] = np.repeat(levels, 500)[:n]
    for j in spec.sensed_joints:
        s = spec.joint(j).components["sensor"]
        lsb = (s["range"][1] - s["range"][0]) / 2.0 ** s["bits"]
        q = 0.3 * np.sin(2 * math.pi * rng.uniform(0.05, 0.5) * t) + rng.normal(0, 3e-4, n)
        cols[f"q_{j}"] = s["A"] * np.round((q - s["B"]) / s["A"] / lsb) * lsb + s["B"]
    for j in spec.joint_names:
        cols[f"p_{j}_a"] = 7e6 + 3e6 * np.sin(0.3 * t + rng.uniform(0, 6)) + rng.normal(0, 2e4, n)
        cols[f"p_{j}_b"] = 7e6 - 3e6 * np.sin(0.3 * t + rng.uniform(0, 6)) + rng.normal(0, 2e4, n)
    return cols


# ---- the reference: the dataset CSV reader and writer before the fast path ------------------------
def reference_read_csv(path) -> Dataset:
    text = Path(path).read_text()
    reader = csv.reader(io.StringIO(text))
    header = [h.strip() for h in next(reader)]
    rows = []
    for r, row in enumerate(reader, start=1):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise ValueError(f"row {r}")
        vals = []
        for cell in row:
            v = float(cell)
            if not math.isfinite(v):
                raise ValueError(f"row {r}")
            vals.append(v)
        rows.append(vals)
    return Dataset(header, np.array(rows, dtype=float))


def reference_write_csv(path, columns) -> None:
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    with open(path, "w", newline="") as fh:
        fh.write(",".join(names) + "\n")
        np.savetxt(fh, data, delimiter=",", fmt="%.10g")


def timed(fn, *args):
    t0 = time.perf_counter()
    out = fn(*args)
    return time.perf_counter() - t0, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=3600.0, help="record length (s) at 1 kHz (default 1 h)")
    ap.add_argument("--no-reference", action="store_true", help="skip the pre-fast-path CSV reader and writer")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    cols = hydrolek_record(args.duration)
    n = cols["time"].size
    res = {"rows": n, "columns": len(cols), "duration_s": args.duration, "formats": {}}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name, path in (("csv", tmp / "r.csv"), ("parquet", tmp / "r.parquet")):
            w, _ = timed(write_dataset, path, cols)
            r, ds = timed(read_dataset, path)
            assert ds.data.shape == (n, len(cols))
            res["formats"][name] = {"write_s": w, "read_s": r, "size_mb": path.stat().st_size / 1e6}
            if name == "csv":
                csv_ds = ds
        if not args.no_reference:
            w, _ = timed(reference_write_csv, tmp / "ref.csv", cols)
            r, ref = timed(reference_read_csv, tmp / "ref.csv")
            assert np.array_equal(ref.data, csv_ds.data), "the fast path reads other values than the reference"
            res["reference_csv"] = {"write_s": w, "read_s": r, "size_mb": (tmp / "ref.csv").stat().st_size / 1e6}
            for f in res["formats"].values():
                f["read_speedup"] = r / f["read_s"]
                f["write_speedup"] = w / f["write_s"]
    if args.json:
        print(json.dumps(res, indent=2))
        return
    print(f"HydroLek record: {n} rows x {len(cols)} columns ({args.duration:g} s at 1 kHz)")
    print(f"{'format':<16} {'write s':>8} {'read s':>8} {'size MB':>8} {'read x':>7} {'write x':>8}")
    rows = list(res["formats"].items()) + ([("csv (reference)", res["reference_csv"])] if "reference_csv" in res else [])
    for name, f in rows:
        print(f"{name:<16} {f['write_s']:8.2f} {f['read_s']:8.2f} {f['size_mb']:8.1f} "
              f"{f.get('read_speedup', 1.0):7.1f} {f.get('write_speedup', 1.0):8.1f}")
    print("read x / write x: the reference's time over this format's (higher is faster)")


if __name__ == "__main__":
    main()
