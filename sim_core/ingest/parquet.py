"""Datasets as Parquet: one float64 column per dataset column (the CSV's names), units and robot in the
schema metadata (``hydrohil.units``: JSON {column: unit}; ``hydrohil.robot``: the robot's name).
The HIL recorder writes the same layout."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .missing import HINT as MISSING_HINT

UNITS_KEY = b"hydrohil.units"
ROBOT_KEY = b"hydrohil.robot"
SUFFIXES = (".parquet", ".pq")


def is_parquet(path: str | Path) -> bool:
    return Path(path).suffix.lower() in SUFFIXES


def _error(msg: str) -> Exception:
    from ..dataset import DatasetError

    return DatasetError(msg)


def write_parquet(path: str | Path, columns: dict[str, np.ndarray], *, units: dict[str, str] | None = None,
                  robot: str | None = None, compression: str = "snappy") -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    meta = {UNITS_KEY: json.dumps(units or {}).encode()}
    if robot:
        meta[ROBOT_KEY] = robot.encode()
    table = pa.table({n: pa.array(np.asarray(v, dtype=np.float64)) for n, v in columns.items()}).replace_schema_metadata(meta)
    pq.write_table(table, str(path), compression=compression)


class ParquetTable:
    """A Parquet file's columns, read on demand as float64 with messages naming column and row."""

    def __init__(self, path: str | Path):
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.path = Path(path)
        if not self.path.is_file():
            raise _error(f"{self.path}: no such file")
        try:
            self._file = pq.ParquetFile(str(self.path))
        except (pa.ArrowException, OSError) as exc:
            raise _error(f"{self.path}: not a readable Parquet file ({exc})") from None
        schema = self._file.schema_arrow
        self.names: list[str] = list(schema.names)
        meta = schema.metadata or {}
        try:
            self.units: dict[str, str] = json.loads(meta.get(UNITS_KEY, b"{}").decode())
        except (ValueError, UnicodeDecodeError):
            raise _error(f"{self.path}: schema metadata hydrohil.units is not JSON") from None
        self.robot: str | None = meta[ROBOT_KEY].decode() if ROBOT_KEY in meta else None
        self.rows = self._file.metadata.num_rows
        self._types = {f.name: f.type for f in schema}

    def clock_kind(self, name: str) -> str | None:
        """'date and time' (a timestamp column), 'time of day' (time32/64) or 'duration' for a column of
        clock readings, else None."""
        import pyarrow as pa

        typ = self._types[name]
        return ("date and time" if pa.types.is_timestamp(typ) else "time of day" if pa.types.is_time(typ)
                else "duration" if pa.types.is_duration(typ) else None)

    def columns(self, names: list[str], clock: int | None = None, missing: bool = False) -> np.ndarray:
        """Columns ``names`` as float64 [rows, k], read in one pass; errors for text columns, missing
        and non-finite values name the column and row. ``clock``: the position of a column that may
        hold clock readings (timestamps, times of day, durations: the time column), read as seconds
        from its first row (a time of day counted on past midnight). ``missing``: a null or NaN
        (not a clock reading's) is read as NaN instead of being an error."""
        import pyarrow as pa
        import pyarrow.compute as pc

        from .clock import past_midnight

        for k, name in enumerate(names):
            typ = self._types[name]
            if k == clock and self.clock_kind(name):
                continue
            if not (pa.types.is_floating(typ) or pa.types.is_integer(typ) or pa.types.is_decimal(typ)):
                raise _error(f"{self.path}: column {name!r} holds {typ}, not numbers")
        try:
            table = self._file.read(columns=list(dict.fromkeys(names)))
        except (pa.ArrowException, OSError) as exc:
            raise _error(f"{self.path}: cannot be read ({exc})") from None
        out = np.empty((table.num_rows, len(names)), order="F")     # column by column: contiguous copies
        for k, name in enumerate(names):
            col = table.column(name)
            kind = self.clock_kind(name) if k == clock else None
            if col.null_count and missing and not kind:
                col = col.cast(pa.float64()).fill_null(float("nan"))
            if col.null_count:
                r = int(pc.index(pc.is_null(col), True).as_py()) + 1
                raise _error(f"{self.path}: column {name!r}: row {r}: empty (a missing value"
                             + ("" if kind else f"; {MISSING_HINT}") + ")")
            if kind:
                ticks = pc.cast(col, pa.int64()).to_numpy()           # integer ticks: exact before scaling
                out[:, k] = (ticks - ticks[0]) * {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}[col.type.unit]
                if kind == "time of day":
                    out[:, k] = past_midnight(out[:, k])[0]
                continue
            out[:, k] = col.to_numpy() if pa.types.is_float64(col.type) else col.cast(pa.float64()).to_numpy()
            bad = np.flatnonzero(~(np.isfinite(out[:, k]) | (missing & np.isnan(out[:, k]))))
            if bad.size:
                r = int(bad[0]) + 1
                raise _error(f"{self.path}: column {name!r}: row {r}: {out[r - 1, k]} is not a finite number"
                             + (f" (a missing value; {MISSING_HINT})" if np.isnan(out[r - 1, k]) else ""))
        return out
