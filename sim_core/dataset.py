"""The dataset CSV format shared by ``excite``, ``simulate``, recordings and ``diagnose``.

Columns: ``time`` (s, strictly increasing), ``u_<joint>`` (V), ``q_<joint>`` (measured angle, rad,
sensed joints), ``p_<joint>_a`` and ``p_<joint>_b`` (chamber pressures, Pa). Errors name the
column and the row (data rows count from 1; the header is line 1 of the file).
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np


class DatasetError(ValueError):
    """The CSV is not a valid dataset; the message names the column and row."""


@dataclass
class Dataset:
    columns: list[str]
    data: np.ndarray  # [rows, columns]

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[:, self.columns.index(name)]
        except ValueError:
            raise KeyError(f"dataset has no column {name!r}") from None

    @property
    def time(self) -> np.ndarray:
        return self["time"]

    def __len__(self) -> int:
        return self.data.shape[0]


def read_csv(path: str | Path) -> Dataset:
    """Read a numeric CSV with a header row; reports the first unreadable cell by column and row."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise DatasetError(f"{path}: no such file") from None
    except UnicodeDecodeError:
        raise DatasetError(f"{path}: not a text CSV file") from None
    reader = csv.reader(io.StringIO(text))
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise DatasetError(f"{path}: empty file (expected a header row)") from None
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise DatasetError(f"{path}: duplicate column(s) {', '.join(dup)}")
    if any(not h for h in header):
        raise DatasetError(f"{path}: empty column name in the header")
    rows = []
    for r, row in enumerate(reader, start=1):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise DatasetError(f"{path}: row {r} (line {r + 1}) has {len(row)} values, the header has {len(header)}")
        vals = []
        for c, cell in enumerate(row):
            try:
                v = float(cell)
            except ValueError:
                raise DatasetError(f"{path}: column {header[c]!r}: row {r} (line {r + 1}): {cell.strip()!r} is not a number") from None
            if not math.isfinite(v):
                raise DatasetError(f"{path}: column {header[c]!r}: row {r} (line {r + 1}): {cell.strip()} is not a finite number")
            vals.append(v)
        rows.append(vals)
    if not rows:
        raise DatasetError(f"{path}: no data rows")
    return Dataset(header, np.array(rows, dtype=float))


def check_time(ds: Dataset, where: str = "") -> None:
    if "time" not in ds:
        raise DatasetError(f"{where}missing column 'time' (s); columns: {', '.join(ds.columns)}")
    t = ds.time
    if t.shape[0] < 2:
        raise DatasetError(f"{where}column 'time': need at least 2 rows")
    d = np.diff(t)
    bad = np.flatnonzero(d <= 0)
    if bad.size:
        r = int(bad[0]) + 2
        raise DatasetError(
            f"{where}column 'time': row {r} (line {r + 1}): {t[r - 1]:g} s is not after the previous {t[r - 2]:g} s "
            "(time must increase strictly)"
        )


def write_csv(path: str | Path, columns: dict[str, np.ndarray]) -> None:
    """Write columns (equal length) with full float precision; time first."""
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        fh.write(",".join(names) + "\n")
        np.savetxt(fh, data, delimiter=",", fmt="%.10g")


def input_matrix(ds: Dataset, spec, where: str = "") -> np.ndarray:
    """Commands [rows, n_act] from ``u_<joint>`` columns (absent joints 0 V), validated against the
    robot: unknown joints and voltages outside a joint's command range are errors."""
    check_time(ds, where)
    joints = spec.joint_names
    allowed_other = {"time"}
    for j in joints:
        allowed_other.add(f"q_{j}")
        allowed_other.update({f"p_{j}_a", f"p_{j}_b"})
    U = np.zeros((len(ds), len(joints)))
    for c, name in enumerate(ds.columns):
        if name.startswith("u_"):
            j = name[2:]
            if j not in joints:
                raise DatasetError(f"{where}column {name!r}: unknown joint {j!r}; joints of {spec.name}: {', '.join(joints)}")
            col = ds.data[:, c]
            lo, hi = spec.joint(j).command_range
            bad = np.flatnonzero((col < lo) | (col > hi))
            if bad.size:
                r = int(bad[0]) + 1
                raise DatasetError(
                    f"{where}column {name!r}: row {r} (line {r + 1}): {col[r - 1]:g} V is outside the joint's "
                    f"command range [{lo:g}, {hi:g}] V"
                )
            U[:, joints.index(j)] = col
        elif name not in allowed_other:
            raise DatasetError(
                f"{where}column {name!r}: not a dataset column for {spec.name} "
                f"(expected time, u_<joint>, q_<joint>, p_<joint>_a, p_<joint>_b; joints: {', '.join(joints)})"
            )
    return U
