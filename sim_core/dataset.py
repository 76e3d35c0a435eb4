"""The dataset format shared by ``excite``, ``simulate``, ``import``, recordings and ``diagnose``, as
CSV or Parquet (chosen by the file suffix: ``.parquet``/``.pq``, else CSV).

Columns: ``time`` (s, strictly increasing), ``u_<joint>`` (V), ``q_<joint>`` (measured position,
sensed joints: rad for a revolute joint, m for a prismatic one), ``p_<joint>_a`` and ``p_<joint>_b``
(chamber pressures, Pa gauge). CSV: a header row, ``,`` between values, 10 significant digits.
Parquet: one float64 column per dataset column, units and robot in the schema metadata (see
:mod:`sim_core.ingest.parquet`). Errors name the column and the row (data rows count from 1; in a
CSV the header is line 1 of the file).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CSV_DIGITS = 10     # significant digits written to a dataset CSV


class DatasetError(ValueError):
    """The file is not a valid dataset; the message names the column and row."""


@dataclass
class Dataset:
    columns: list[str]
    data: np.ndarray  # [rows, columns] (column-major when read from a file: columns are contiguous)
    units: dict[str, str] = field(default_factory=dict)   # as stored in the file (Parquet metadata), if any
    robot: str | None = None                               # as stored in the file, if any

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


def column_unit(name: str, spec=None) -> str:
    """SI unit of a dataset column (a ``q_`` column is in m on a prismatic joint of ``spec``)."""
    if name == "time":
        return "s"
    if name.startswith("u_"):
        return "V"
    if name.startswith("p_"):
        return "Pa"
    if name.startswith("q_"):
        if spec is not None and name[2:] in spec.joint_names:
            from .ingest.columns import PRISMATIC, joint_type

            return "m" if joint_type(spec, name[2:]) == PRISMATIC else "rad"
        return "rad"
    return ""


def dataset_units(columns, spec=None) -> dict[str, str]:
    return {c: column_unit(c, spec) for c in columns}


def read_dataset(path: str | Path) -> Dataset:
    """A dataset file, CSV or Parquet by suffix."""
    from .ingest.parquet import is_parquet

    return read_parquet(path) if is_parquet(path) else read_csv(path)


def write_dataset(path: str | Path, columns: dict[str, np.ndarray], *, spec=None, robot: str | None = None) -> None:
    """Write a dataset, CSV or Parquet by suffix (Parquet records units and the robot)."""
    from .ingest.parquet import is_parquet

    if is_parquet(path):
        write_parquet(path, columns, units=dataset_units(columns, spec),
                      robot=robot or (spec.name if spec is not None else None))
    else:
        write_csv(path, columns)


def read_csv(path: str | Path) -> Dataset:
    """Read a numeric CSV with a header row; reports the first unreadable cell by column and row."""
    from .ingest.text import open_text, read_columns

    layout = open_text(path, header=True, delimiter=",")
    cols = read_columns(layout, list(range(len(layout.names))), [repr(n) for n in layout.names])
    return Dataset(list(layout.names), cols.data)


def read_parquet(path: str | Path) -> Dataset:
    """A dataset Parquet file; units other than the dataset's SI units are refused (read such a file
    with ``--column NAME=NAME:UNIT``)."""
    from .ingest.parquet import ParquetTable

    pt = ParquetTable(path)
    if pt.rows == 0:
        raise DatasetError(f"{path}: no data rows")
    for name, unit in pt.units.items():
        si = column_unit(name)
        if si and unit not in (si, "m" if si == "rad" else si):
            raise DatasetError(f"{path}: column {name!r} is in {unit} (schema metadata hydrohil.units); a dataset is "
                               f"in SI units ({si}): read it with --column {name}={name}:{unit}")
    data = pt.columns(pt.names)
    return Dataset(list(pt.names), data, dict(pt.units), pt.robot)


def write_parquet(path: str | Path, columns: dict[str, np.ndarray], *, units: dict[str, str] | None = None,
                  robot: str | None = None) -> None:
    from .ingest.parquet import write_parquet as _write

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write(path, columns, units=units if units is not None else dataset_units(columns), robot=robot)


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
    """Write columns (equal length) with CSV_DIGITS significant digits; time first."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    names = list(columns)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    table = pa.table({n: pa.array(round_significant(np.asarray(columns[n], dtype=float), CSV_DIGITS)) for n in names})
    with open(path, "wb") as fh:
        fh.write((",".join(names) + "\n").encode())
        pacsv.write_csv(table, fh, pacsv.WriteOptions(include_header=False))


def round_significant(x: np.ndarray, digits: int) -> np.ndarray:
    """``x`` rounded to ``digits`` significant decimal digits, value for value what ``%.{digits}g``
    prints, so that the shortest text of each value (what the CSV writer prints) has at most that
    many digits. Vectorised; values near a rounding tie, and those beyond the range where powers of
    ten are exact doubles, are formatted one by one."""
    x = np.asarray(x, dtype=float)
    nz = np.isfinite(x) & (x != 0.0)
    v = np.where(nz, x, 1.0)
    with np.errstate(over="ignore", under="ignore"):
        k = (digits - 1) - np.floor(np.log10(np.abs(v)))
        up = k >= 0
        p = 10.0 ** np.clip(np.abs(k), 0, 22)
        scaled = np.where(up, v * p, v / p)
        rs = np.round(scaled)
        r = np.where(up, rs / p, rs * p)
    # |scaled| < 10**digits: a few ulps around .5 may be a tie the scaling moved; |k| > 22: inexact powers
    slow = np.flatnonzero(nz & ((np.abs(np.abs(scaled - np.trunc(scaled)) - 0.5) < 1e-5) | (np.abs(k) > 22)))
    r[slow] = [float(f"{a:.{digits}g}") for a in x[slow]]
    return np.where(nz, r, x)


def check_command_range(u: np.ndarray, joint, *, where: str, label: str, place, hint: str = "") -> None:
    """Commands (V) of ``joint`` (a JointSpec) inside its command range; ``place(row)`` names a row."""
    lo, hi = joint.command_range
    bad = np.flatnonzero((u < lo) | (u > hi))
    if bad.size:
        r = int(bad[0]) + 1
        raise DatasetError(f"{where}column {label}: {place(r)}: {u[r - 1]:g} V is outside the joint's command range "
                           f"[{lo:g}, {hi:g}] V{hint}; if the valve's amplifier does take such commands, widen "
                           f"joints.{joint.name}.cfp.command_range in the robot's spec")


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
            check_command_range(col, spec.joint(j), where=where, label=repr(name), place=lambda r: f"row {r} (line {r + 1})")
            U[:, joints.index(j)] = col
        elif name not in allowed_other:
            raise DatasetError(
                f"{where}column {name!r}: not a dataset column for {spec.name} "
                f"(expected time, u_<joint>, q_<joint>, p_<joint>_a, p_<joint>_b; joints: {', '.join(joints)})"
            )
    return U
