"""A record's date, so that a fleet's parameters can be followed over time.

From the file name (``--date-from name``, the default): the first date in it, written
YYYY-MM-DD, YYYY_MM_DD or YYYYMMDD, optionally followed by a time (HH:MM[:SS], HH-MM[-SS] or HHMM[SS]
after 'T', '_', '-' or a space). From a column (``--date-from SOURCE``, a header name or 0-based
index of the file, laid out as the reading options say): its first value, an ISO 8601 date and time
or Unix time in seconds. Dates are naive (the logger's clock); a time zone given in the file is
converted to UTC.
"""

from __future__ import annotations

import csv
import io
import math
import re
from datetime import datetime, timezone
from pathlib import Path

_NAME = re.compile(
    r"(?<!\d)(?P<y>(?:19[7-9]|20\d)\d)(?P<s>[-_]?)(?P<m>[01]\d)(?P=s)(?P<d>[0-3]\d)"
    r"(?:[T_ -](?P<H>[0-2]\d)[:-]?(?P<M>[0-5]\d)(?:[:-]?(?P<S>[0-5]\d))?)?(?!\d)")


class DateError(ValueError):
    pass


def date_from_name(name: str) -> datetime | None:
    for m in _NAME.finditer(name):
        try:
            return datetime(int(m["y"]), int(m["m"]), int(m["d"]), int(m["H"] or 0), int(m["M"] or 0), int(m["S"] or 0))
        except ValueError:       # 20241399: not a date, look further
            continue
    return None


def parse_date(value, where: str) -> datetime:
    """ISO 8601 text, a datetime, or Unix seconds."""
    if isinstance(value, datetime):
        dt = value
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        if not math.isfinite(value):
            raise DateError(f"{where}: {value!r} is not a date")
        dt = datetime.fromtimestamp(float(value), tz=timezone.utc)
    else:
        text = str(value).strip().strip('"')
        try:
            return parse_date(float(text), where)
        except ValueError:
            pass
        try:
            dt = datetime.fromisoformat(text.replace("Z", "+00:00"))
        except ValueError:
            raise DateError(f"{where}: {text!r} is neither an ISO 8601 date (2024-03-01T06:00) nor Unix seconds") from None
    if dt.tzinfo is not None:
        dt = dt.astimezone(timezone.utc).replace(tzinfo=None)
    return dt


def date_from_column(path: Path, source: str, options) -> datetime:
    """The first value of file column ``source`` (header name or 0-based index)."""
    from ..ingest.parquet import is_parquet

    where = f"{path}: --date-from {source}"
    if is_parquet(path):
        import pyarrow.parquet as pq

        names = pq.read_schema(path).names
        name = names[int(source)] if source.isdigit() and int(source) < len(names) else source
        if name not in names:
            raise DateError(f"{where}: no such column; columns: {', '.join(names)}")
        col = pq.ParquetFile(path).read_row_group(0, columns=[name]).column(0)
        if len(col) == 0:
            raise DateError(f"{where}: the column is empty")
        return parse_date(col[0].as_py(), where)
    from ..ingest.text import open_text, parse_delimiter

    layout = open_text(path, header=False if options.no_header else None,
                       delimiter=parse_delimiter(options.delimiter), skip_rows=options.skip_rows)
    if source.isdigit():
        index = int(source)
        if index >= layout.n_columns:
            raise DateError(f"{where}: column index out of range (0..{layout.n_columns - 1})")
    elif layout.names is not None and source in layout.names:
        index = layout.names.index(source)
    else:
        have = f"columns: {', '.join(layout.names)}" if layout.names else "the file has no header: use a 0-based index"
        raise DateError(f"{where}: no such column; {have}")
    with open(path, "rb") as fh:
        fh.seek(layout.data_offset)
        line = fh.readline().decode("utf-8", errors="replace").rstrip("\r\n")
    cells = line.split() if layout.delimiter is None else next(csv.reader(io.StringIO(line), delimiter=layout.delimiter))
    if index >= len(cells) or not cells[index].strip():
        raise DateError(f"{where}: line {layout.data_line} has no value in that column")
    return parse_date(cells[index], f"{where} (line {layout.data_line})")


def record_date(path: Path, name: str, date_from: str, options) -> datetime | None:
    if date_from == "name":
        return date_from_name(Path(path).name) or date_from_name(name)
    return date_from_column(Path(path), date_from, options)


def iso(dt: datetime | None) -> str | None:
    if dt is None:
        return None
    return dt.date().isoformat() if (dt.hour, dt.minute, dt.second, dt.microsecond) == (0, 0, 0, 0) else dt.isoformat()
