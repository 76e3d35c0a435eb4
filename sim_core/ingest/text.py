"""Delimited text tables as loggers write them: with or without a header row, any delimiter, a
preamble to skip, decimal commas, a last line cut short.

Two steps: :func:`open_text` reads only the first lines (layout: delimiter, header, where the data
starts); :func:`read_columns` reads the wanted columns as float64. The fast path is pyarrow's CSV
reader (``np.loadtxt`` for whitespace-separated files); if it fails, or the result holds a missing
or non-finite value, the slow path reads the file again line by line to name the column, row and
line of the first bad cell. Rows count data rows from 1 (blank lines are not rows); lines count
the file's lines from 1.
"""

from __future__ import annotations

import array
import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import clock as clock_readings
from .missing import HINT as MISSING_HINT
from .missing import is_missing

BINARY_PROBE = 8192             # bytes looked at to tell a text file from a binary one
COMMENT_MARKS = ("#", "%")      # a preamble's lines before the table (a logger's notes, MATLAB's '%')
_NUMBER_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+([eE][+-]?\d+)?$")
DELIMITER_WORDS = {"tab": "\t", "\\t": "\t", "space": None, "whitespace": None, " ": None,
                   "comma": ",", "semicolon": ";"}


def _error(msg: str) -> Exception:
    from ..dataset import DatasetError

    return DatasetError(msg)


@dataclass
class TextLayout:
    """Where the data of a text table is and how its lines split."""

    path: Path
    delimiter: str | None           # one character, or None: runs of whitespace
    decimal: str                    # '.' or ','
    names: list[str] | None         # header row, None when the file has none
    n_fields: int                   # values per row (from the header or the first data row)
    data_offset: int                # byte offset of the first data line
    data_line: int                  # its line number (from 1)
    notes: list[str] = field(default_factory=list)

    trailing: bool = False          # every row ends with a delimiter: one empty field more, not a column
    units: list[str] | None = None  # a row of units under the header (s, V, bar ...), one per name, else None

    @property
    def n_columns(self) -> int:
        """Columns that hold data (the empty field after a trailing delimiter is none)."""
        return self.n_fields - 1 if self.trailing else self.n_fields

    @property
    def first_row_label(self) -> str:
        return "the header" if self.names is not None else f"line {self.data_line} (the first row)"


@dataclass
class TextColumns:
    """Wanted columns of a text table as float64, with the file line of each row."""

    data: np.ndarray                # [rows, k]
    layout: TextLayout
    _lines: np.ndarray | None = None
    clock: str | None = None        # the clock column's readings: 'date and time' or 'time of day' (in seconds)

    def line(self, row: int) -> int:
        """File line number of data row ``row`` (from 1)."""
        if self._lines is None:
            self._lines = _data_lines(self.layout)
        return int(self._lines[row - 1])


def parse_delimiter(text: str | None) -> str | None | bool:
    """``--delimiter`` value: one character, 'tab', 'space'/'whitespace' (runs of blanks); None: detect.
    Returns the character, None for whitespace, or False for 'detect'."""
    if text is None:
        return False
    key = text if text in DELIMITER_WORDS else text.lower()
    if key in DELIMITER_WORDS:
        return DELIMITER_WORDS[key]
    if len(text) != 1 or text in "\r\n\"" or text.isalnum() or text in ".+-":
        raise _error(f"--delimiter {text!r}: expected one character (e.g. ',' ';' '|'), 'tab' or 'space'")
    return text


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    return next(csv.reader([line], delimiter=delimiter))


def _to_float(cell: str, decimal: str) -> float:
    s = cell.strip()
    if decimal == ",":
        s = s.replace(",", ".")
    return float(s)


def _is_number(cell: str, decimal: str) -> bool:
    try:
        _to_float(cell, decimal)
        return True
    except ValueError:
        return False


def open_text(path: str | Path, *, header: bool | None = None, delimiter: str | None | bool = False,
              skip_rows: int = 0) -> TextLayout:
    """Layout of a text table. ``header``: True, False, or None to detect (a first line of numbers
    only is data); ``delimiter``: a character, None for whitespace, False to detect."""
    path = Path(path)
    if skip_rows < 0:
        raise _error(f"--skip-rows {skip_rows}: must be 0 or more")
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        raise _error(f"{path}: no such file") from None
    except IsADirectoryError:
        raise _error(f"{path}: is a directory, not a file") from None
    except OSError as exc:
        raise _error(f"{path}: cannot be read ({exc.strerror})") from None
    notes: list[str] = []
    with fh:
        probe = fh.read(BINARY_PROBE)
        if not probe.strip():
            raise _error(f"{path}: empty file")
        if b"\x00" in probe:
            raise _error(f"{path}: not a text file (binary data); expected delimited text (CSV) or Parquet")
        fh.seek(0)
        offset = 3 if probe.startswith(b"\xef\xbb\xbf") else 0   # UTF-8 byte-order mark (spreadsheet exports)
        fh.seek(offset)
        lineno = 0
        comments: list[tuple[str, int, int]] = []   # a preamble of comment lines before the table
        lines: list[tuple[str, int, int]] = []      # (text, line, offset) of the first non-blank lines after it
        for raw in fh:
            lineno += 1
            start, offset = offset, offset + len(raw)
            if lineno <= skip_rows:
                continue
            text = _decode(raw).rstrip("\r\n")
            if not text.strip():
                continue
            if not lines and text.lstrip()[:1] in COMMENT_MARKS:
                comments.append((text, lineno, start))
                continue
            lines.append((text, lineno, start))
            if len(lines) == 3:
                break
    first, second, third = (lines + [None, None, None])[:3]
    if comments:
        mark = comments[0][0].lstrip()[0]
        span = f"line {comments[0][1]}" if len(comments) == 1 else f"lines {comments[0][1]}-{comments[-1][1]}"
        notes.append(f"{span} start{'s' if len(comments) == 1 else ''} with {mark!r}: a preamble, skipped")
    preamble_note = len(notes) - 1
    if first is None:
        if comments:
            raise _error(f"{path}: nothing but comment lines ({len(comments)}, starting with "
                         f"{comments[0][0].lstrip()[0]!r})")
        if skip_rows:
            raise _error(f"{path}: nothing left after skipping {skip_rows} line(s) (--skip-rows)")
        raise _error(f"{path}: empty file")
    if delimiter is False:
        delimiter = _detect_delimiter(first[0])
        if delimiter != ",":
            notes.append(f"delimiter: {_delimiter_name(delimiter)} (detected)")
    data_text = second[0] if second is not None else first[0]
    decimal = "."
    if delimiter != ",":
        cells = _split(data_text, delimiter)
        if any(_NUMBER_DECIMAL_COMMA.match(c.strip()) for c in cells) and not any("." in c for c in cells):
            decimal = ","
            notes.append("decimal separator: comma (detected)")
    cells = [c.strip() for c in _split(first[0], delimiter)]
    if header is None:
        header = not _numbers_only(cells, decimal)
        named = _commented_header(comments, delimiter, len(cells), decimal) if not header else None
        if named is not None:
            # the preamble's last line names the columns (numpy's savetxt writes "# time,q,u")
            notes[preamble_note] += f"; its last line, line {comments[-1][1]}, names the columns"
            return _with_units(TextLayout(path, delimiter, decimal, named, len(named), first[2], first[1], notes),
                               first, second, decimal)
        if not header:
            notes.append(f"no header row: line {first[1]} holds numbers only, read as data (columns by 0-based index)")
    if not header:
        trailing = len(cells) > 1 and not cells[-1]
        if trailing:
            notes.append("every row ends with a delimiter: the empty field after it is not a column")
        return TextLayout(path, delimiter, decimal, None, len(cells), first[2], first[1], notes, trailing)
    names = [c.strip('"') for c in (cells[:-1] if len(cells) > 1 and not cells[-1] else cells)]
    if any(not n for n in names):
        raise _error(f"{path}: line {first[1]}: empty column name in the header (column {names.index('')})")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise _error(f"{path}: duplicate column(s) {', '.join(dup)}")
    if second is None:
        raise _error(f"{path}: no data rows after the header (line {first[1]})")
    data_cells = _split(data_text, delimiter)
    trailing = len(data_cells) == len(names) + 1 and not data_cells[-1].strip()
    if trailing:
        notes.append("every row ends with a delimiter: the empty field after it is not a column")
    return _with_units(TextLayout(path, delimiter, decimal, names, len(names) + trailing, second[2], second[1], notes,
                                  trailing), second, third, decimal)


def _numbers_only(cells: list[str], decimal: str) -> bool:
    """Whether a line's non-empty cells are all numbers or clock readings (a data row)."""
    return all(_is_number(c, decimal) or clock_readings.kind(c) for c in cells if c)


def _commented_header(comments: list[tuple[str, int, int]], delimiter: str | None, n: int,
                      decimal: str) -> list[str] | None:
    """The column names on the preamble's last comment line, where it splits into the data's ``n``
    fields of which none is a number; else None."""
    if not comments:
        return None
    text = comments[-1][0].lstrip()[1:]
    names = [c.strip().strip('"') for c in _split(text, delimiter)]
    if len(names) != n or any(not c for c in names) or any(_is_number(c, decimal) for c in names) \
            or len(set(names)) != n:
        return None
    return names


def _with_units(layout: TextLayout, line: tuple[str, int, int] | None, after: tuple[str, int, int] | None,
                decimal: str) -> TextLayout:
    """``layout`` with a row of units under its header taken out of the data: ``line`` (the first line
    after the header) holds no number, as many fields as the header, and numbers follow on ``after``."""
    if line is None or after is None or layout.names is None:
        return layout
    cells = [c.strip() for c in _split(line[0], layout.delimiter)]
    if layout.trailing and len(cells) == layout.n_fields and not cells[-1]:
        cells = cells[:-1]
    if len(cells) != len(layout.names) or not any(cells) or any(_is_number(c, decimal) or clock_readings.kind(c)
                                                                for c in cells if c):
        return layout
    if not _numbers_only([c.strip() for c in _split(after[0], layout.delimiter)], decimal):
        return layout
    layout.units = [_unit_text(c) for c in cells]
    layout.data_offset, layout.data_line = after[2], after[1]
    layout.notes.append(f"line {line[1]} holds no number under the header ({', '.join(repr(c) for c in cells)}): "
                        f"a row of units, read as the columns' units where --column gives none")
    return layout


def _unit_text(cell: str) -> str:
    """A units row's cell without the brackets some loggers put around it: '[s]', '(bar)'."""
    cell = cell.strip().strip('"')
    if len(cell) > 2 and cell[0] + cell[-1] in ("[]", "()", "{}"):
        cell = cell[1:-1].strip()
    return cell


def _detect_delimiter(line: str) -> str | None:
    """The delimiter of a header or data line: tab, semicolon, comma, bar, else runs of whitespace
    (';' and tab win over ',' so that decimal commas stay inside their cells)."""
    for d in ("\t", ";", ",", "|"):
        if d in line:
            return d
    return None if len(line.split()) > 1 else ","


def _delimiter_name(d: str | None) -> str:
    return {None: "whitespace", "\t": "tab", ";": "';'", ",": "','", "|": "'|'"}.get(d, repr(d))


def read_columns(layout: TextLayout, indices: list[int], labels: list[str], *, cut_last_line: bool = False,
                 clock: int | None = None, missing: bool = False) -> TextColumns:
    """Columns ``indices`` (0-based) as float64 [rows, k]; ``labels`` name them in messages.
    ``cut_last_line``: a last row with too few values (a logger stopped mid-line) is dropped with a
    note instead of being an error. ``clock``: the position (in ``indices``) of a column that may
    hold clock readings (:mod:`.clock`, the time column): when its first cell is one, every cell
    must be one of the same kind, read as seconds (a time of day past midnight counted on).
    ``missing``: a cell that holds no sample (:func:`.missing.is_missing`) is read as NaN instead of
    being an error."""
    reading = None
    if clock is not None:
        rows = _rows(layout)
        first = next(rows, (0, []))[1]
        rows.close()
        cell = first[indices[clock]] if indices[clock] < len(first) else ""
        if not _is_number(cell, layout.decimal):
            reading = clock_readings.kind(cell)
    if reading is None:
        data = _fast(layout, indices)
        if data is None or not np.isfinite(data).all():
            return _slow(layout, indices, labels, cut_last_line, missing=missing)
        if data.shape[0] == 0:
            raise _error(f"{layout.path}: no data rows")
        return TextColumns(data, layout)
    out = _slow(layout, indices, labels, cut_last_line, clock=(clock, reading, clock_readings.whole_seconds(cell)),
                missing=missing)
    out.clock = reading
    passed = 0
    if reading == "time of day":
        out.data[:, clock], passed = clock_readings.past_midnight(out.data[:, clock])
    layout.notes.append(f"column {labels[clock]}: clock readings ({reading}), read as seconds from the first row"
                        + (f"; the clock passed midnight {passed} time(s), a day added each time" if passed else ""))
    return out


def _fast(layout: TextLayout, indices: list[int]) -> np.ndarray | None:
    """pyarrow (one-character delimiter) or np.loadtxt (whitespace); None if either refuses."""
    if not indices:
        return None
    if layout.delimiter is None:
        try:
            with open(layout.path, "rb") as fh:
                fh.seek(layout.data_offset)
                out = np.loadtxt(fh, usecols=indices, ndmin=2, comments=None, dtype=float)
        except (ValueError, IndexError):
            return None
        return out
    import pyarrow as pa
    import pyarrow.csv as pacsv

    names = [f"c{i}" for i in range(layout.n_fields)]
    wanted = [names[i] for i in indices]
    read = list(dict.fromkeys(wanted + ([names[-1]] if layout.trailing else [])))   # after a trailing delimiter: empty
    try:
        with pa.memory_map(str(layout.path)) as src:
            src.seek(layout.data_offset)
            table = pacsv.read_csv(
                src,
                read_options=pacsv.ReadOptions(column_names=names),
                parse_options=pacsv.ParseOptions(delimiter=layout.delimiter),
                convert_options=pacsv.ConvertOptions(column_types={n: pa.float64() for n in read},
                                                     include_columns=read, decimal_point=layout.decimal),
            )
    except (pa.ArrowException, OSError):
        return None
    if any(table.column(n).null_count for n in wanted):
        return None
    if layout.trailing and table.column(names[-1]).null_count != table.num_rows:
        return None
    out = np.empty((table.num_rows, len(wanted)), order="F")     # column by column: contiguous copies
    for k, n in enumerate(wanted):
        out[:, k] = table.column(n).to_numpy()
    return out


def _rows(layout: TextLayout):
    """(line number, cells) of every non-blank data line, from the first data line on."""
    with open(layout.path, "rb") as fh:
        fh.seek(layout.data_offset)
        text = io.TextIOWrapper(fh, encoding="utf-8", errors="replace", newline="")
        if layout.delimiter is None:
            for i, line in enumerate(text):
                cells = line.split()
                if cells:
                    yield layout.data_line + i, cells
            return
        reader = csv.reader(text, delimiter=layout.delimiter)
        for cells in reader:
            if not cells or all(not c.strip() for c in cells):
                continue
            yield layout.data_line + reader.line_num - 1, cells


def _data_lines(layout: TextLayout) -> np.ndarray:
    return np.fromiter((ln for ln, _ in _rows(layout)), dtype=np.int64)


def _slow(layout: TextLayout, indices: list[int], labels: list[str], cut_last_line: bool,
          clock: tuple[int, str, int] | None = None, missing: bool = False) -> TextColumns:
    """Line by line: the exact column, row and line of the first bad cell. ``clock``: (position,
    kind, whole seconds of the first reading) of a column of clock readings, read as seconds after
    the first reading's whole second. ``missing``: cells holding no sample read as NaN."""
    path, n = layout.path, layout.n_fields
    cols = [array.array("d") for _ in indices]
    lines = array.array("q")
    short: tuple[int, int, int] | None = None        # (row, line, values) of a row with too few values
    row = 0
    for line, cells in _rows(layout):
        if short is not None:   # a short row that is not the last one
            r, ln, k = short
            raise _error(f"{path}: row {r} (line {ln}) has {k} values, {layout.first_row_label} has {layout.n_columns}")
        row += 1
        if layout.trailing and len(cells) == n and cells[-1].strip():
            raise _error(f"{path}: row {row} (line {line}) has {n} values, {layout.first_row_label} has {layout.n_columns} "
                         f"(and a trailing delimiter)")
        if len(cells) != n:
            if len(cells) < n and cut_last_line:
                short = (row, line, len(cells))
                continue
            raise _error(f"{path}: row {row} (line {line}) has {len(cells)} values, {layout.first_row_label} has "
                         f"{layout.n_columns}")
        if layout.names is not None and [c.strip().strip('"') for c in cells[:len(layout.names)]] == layout.names:
            raise _error(f"{path}: row {row} (line {line}) repeats the header: a second run appended by the logger; "
                         f"split the file before line {line} and read each run on its own (one as --validation)")
        for k, c in enumerate(indices):
            cell = cells[c]
            if missing and is_missing(cell) and (clock is None or k != clock[0]):     # not a clock reading's
                cols[k].append(float("nan"))
                continue
            if clock is not None and k == clock[0]:
                r = clock_readings.reading(cell)
                if r is None or r[0] != clock[1]:
                    what = f"is empty (a missing value; {MISSING_HINT})" if not cell.strip() else \
                        f"{cell.strip()!r} is not a {clock[1]}"
                    raise _error(f"{path}: column {labels[k]}: row {row} (line {line}): {what}, where the first row "
                                 f"holds a {clock[1]} (the column is read as clock readings)")
                cols[k].append(clock_readings.seconds_of(r, clock[2]))
                continue
            try:
                v = _to_float(cell, layout.decimal)
            except ValueError:
                what = f"is empty (a missing value; {MISSING_HINT})" if not cell.strip() else \
                    f"{cell.strip()!r} is not a number" + (f" (a missing value; {MISSING_HINT})" if is_missing(cell) else "")
                if re.fullmatch(r"\d{4}-\d{2}-\d{2}", cell.strip()) and layout.delimiter is None:
                    what += (" but a date: with blanks between the columns a date and its time of day are two "
                             "columns; map the time of day as the time column")
                raise _error(f"{path}: column {labels[k]}: row {row} (line {line}): {what}") from None
            if v != v or v in (float("inf"), float("-inf")):
                raise _error(f"{path}: column {labels[k]}: row {row} (line {line}): {cell.strip()} is not a finite number"
                             + (f" (a missing value; {MISSING_HINT})" if v != v else ""))
            cols[k].append(v)
        lines.append(line)
    if short is not None:
        r, ln, k = short
        layout.notes.append(f"row {r} (line {ln}), the last, has {k} of {layout.n_columns} values (cut short when logging "
                            f"stopped): dropped")
    if not lines:
        raise _error(f"{path}: no data rows")
    data = np.column_stack([np.frombuffer(c, dtype=float) for c in cols]) if cols else np.zeros((len(lines), 0))
    return TextColumns(data, layout, np.frombuffer(lines, dtype=np.int64))
