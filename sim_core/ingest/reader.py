"""A measured record into a dataset of a robot: columns mapped by ``--column``, converted to SI,
checked (time grid, converter saturation, command range) and reported.

:func:`import_record` is ``hydrohil import``; :func:`read_input` is what ``simulate``, ``fit`` and
``diagnose`` call: a dataset file as it is when no reading option is given, else the import.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ..dataset import Dataset, DatasetError, check_command_range, check_time, read_dataset
from . import joint_range, pressure_band
from .columns import ColumnMap, column_kind, dataset_order, parse_column
from .counter_wrap import unwrapped
from .glitches import Glitches, find_glitches, repaired
from .missing import MAX_RUN, Missing, filled
from .options import ReadOptions
from .parquet import ParquetTable, is_parquet
from .runs import rows_text, runs
from .saturation import Saturation, find_saturation
from .text import TextLayout, open_text, parse_delimiter, read_columns
from .timegrid import TimeGrid, check_grid, regular_grid
from .units import KIND_TEXT, SENSOR_VOLTS, Unit, allowed, parse_unit, si_unit

MEASURED_KINDS = ("angle", "position", "pressure")
POSITION_KINDS = ("angle", "position")     # where a glitch is physically impossible (the joint's inertia)


@dataclass
class ColumnReport:
    """One dataset column: where it came from, its unit, and what it holds after conversion."""

    name: str
    source: str                 # "column 3" or "header 'pos_mm'"
    unit: Unit
    min: float
    max: float
    saturation: Saturation | None = None
    glitches: Glitches | None = None       # in the column's raw units
    missing: Missing | None = None         # samples the log did not hold, filled (--missing repair)

    def to_dict(self) -> dict:
        return {"source": self.source, "unit": self.unit.text, "si_unit": self.unit.si,
                "conversion": {"scale": self.unit.scale, "offset": self.unit.offset, "text": self.unit.describe()},
                "min": self.min, "max": self.max,
                "saturation": self.saturation.to_dict() if self.saturation else None,
                "glitches": self.glitches.to_dict() if self.glitches else None,
                "missing": self.missing.to_dict() if self.missing else None}


@dataclass
class ImportResult:
    """A record read for a robot: the dataset (SI, time from 0) and what was found on the way."""

    source: str
    robot: str
    dataset: Dataset
    columns: list[ColumnReport]
    grid: TimeGrid
    notes: list[str] = field(default_factory=list)
    valid: dict[str, np.ndarray] = field(default_factory=dict)   # measured column -> False where saturated
    options: ReadOptions | None = None
    files: list[str] = field(default_factory=list)      # the file(s) read, side by side

    def to_dict(self) -> dict:
        """The JSON sidecar: which column was what, the time grid and the notes."""
        return {
            "source": self.source, "files": list(self.files) or [self.source], "robot": self.robot,
            "rows": len(self.dataset),
            "rate_hz": self.grid.rate_hz, "duration_s": self.grid.duration_s,
            "time_grid": self.grid.to_dict(),
            "columns": {c.name: c.to_dict() for c in self.columns},
            "masked": {name: _false_runs(ok) for name, ok in self.valid.items()},
            "options": self.options.to_dict() if self.options else None,
            "notes": list(self.notes),
        }

    def summary_lines(self) -> list[str]:
        g = self.grid
        out = [f"{self.source}: {len(self.dataset)} rows, {g.rate_hz:.4g} Hz (median period {1e3 * g.median_period_s:.4g} ms), "
               f"{g.duration_s:.4g} s"]
        w = max(len(c.name) for c in self.columns)
        for c in self.columns:
            sat = f"  SATURATED {c.saturation.samples} sample(s)" if c.saturation else ""
            sat += f"  GLITCHES {c.glitches.samples} sample(s)" if c.glitches else ""
            sat += f"  MISSING {c.missing.samples} sample(s) filled" if c.missing else ""
            out.append(f"  {c.name:<{w}} <- {c.source} ({c.unit.describe()}): {c.min:.6g} .. {c.max:.6g} {c.unit.si}{sat}")
        return out


def _false_runs(ok: np.ndarray) -> list[list[int]]:
    """[first, last] dataset rows (0-based) of each run of False."""
    return [[a, b] for a, b in runs(~ok)]


def read_input(path: str | Path, spec, options: ReadOptions | None = None) -> ImportResult:
    """The record ``simulate``, ``fit`` and ``diagnose`` read: with no reading option given, a dataset
    file (CSV or Parquet) taken as it is, under the dataset's strict rules; else :func:`import_record`."""
    if options is not None and options.given:
        return import_record(path, spec, options)
    where = f"{path}: "
    ds = read_dataset(path)
    check_time(ds, where)
    notes = []
    if ds.robot and ds.robot != spec.name:
        notes.append(f"{path}: recorded on robot {ds.robot!r}, read for {spec.name!r}")
    t = ds.time
    place = (lambda r: f"row {r}") if is_parquet(path) else (lambda r: f"row {r} (line {r + 1})")
    grid, _ = check_grid(t, where=where, label="'time'", place=place)
    reports = []
    policy = options.glitches if options is not None else "repair"
    for c, name in enumerate(ds.columns):
        try:
            kind, _ = column_kind(name, spec)
        except ValueError:
            continue
        unit = parse_unit(None, kind, column=name)
        found = None
        if kind in POSITION_KINDS:
            fixed, found = _glitch_check(ds.data[:, c], policy, where, f"column {name}", unit, place, notes)
            if found is not None:
                ds.data = ds.data.copy() if not ds.data.flags.writeable else ds.data
                ds.data[:, c] = fixed
        col = ds.data[:, c]
        reports.append(ColumnReport(name, f"header {name!r}", unit, float(col.min()), float(col.max()), None, found))
    return ImportResult(str(path), spec.name, ds, reports, grid, notes, {}, options)


def import_record(path: str | Path | Sequence[str | Path], spec, options: ReadOptions) -> ImportResult:
    """Read a log file (delimited text or Parquet) as a dataset of ``spec``. Errors
    (:class:`DatasetError`) name the file, the column and the row.

    ``path`` may be several files holding one record side by side (loggers that write one channel
    per file): row k of each is the same sample, and their columns are numbered on from the first
    file's (a second file's column 0 is column ``n`` when the first has ``n``)."""
    paths = [Path(p) for p in ([path] if isinstance(path, (str, Path)) else path)]
    if not paths:
        raise DatasetError("no log file given")
    maps = [parse_column(c) for c in options.columns]
    seen: dict[str, str] = {}
    for m in maps:
        column_kind(m.name, spec)      # a dataset column of this robot
        if m.name in seen:
            raise DatasetError(f"--column {m.text!r}: {m.name} is already mapped by --column {seen[m.name]!r}")
        seen[m.name] = m.text
    if options.rate is not None and not (np.isfinite(options.rate) and options.rate > 0):
        raise DatasetError(f"--rate {options.rate:g}: must be a positive number of samples per second (Hz)")
    source = _open_source(paths[0], options) if len(paths) == 1 else _JoinedSource(paths, options)
    path = source.path            # several files: "a.txt + b.txt"
    where = f"{path}: "
    notes = source.notes          # the source adds to it while reading (a cut last line)
    maps = maps + source.implicit_maps(maps, spec, notes)
    if not maps:
        raise DatasetError(f"{where}no column maps to the dataset of {spec.name}: map them with --column NAME=SOURCE[:UNIT] "
                           f"(e.g. --column time=0:s --column u_{spec.joint_names[0]}=1:V)")
    has_time = any(m.name == "time" for m in maps)
    if all(m.name == "time" for m in maps):
        raise DatasetError(f"{where}only a time column is mapped: map the record's u_<joint>, q_<joint> or p_<joint>_a/_b "
                           f"columns with --column NAME=SOURCE[:UNIT]")
    if has_time and options.rate is not None:
        raise DatasetError(f"{where}both a time column and --rate {options.rate:g}: give one (the time column keeps the "
                           f"real grid, --rate assumes a regular one)")
    if not has_time and options.rate is None:
        raise DatasetError(f"{where}no time column: map one with --column time=SOURCE[:s|ms], or give the sample rate "
                           f"with --rate HZ")
    units = [_unit(m, spec, source) for m in maps]
    labels = [source.label(m) for m in maps]          # where each column comes from
    k_time = next((i for i, m in enumerate(maps) if m.name == "time"), None)
    raw, place = source.read([m.source for m in maps], [f"{m.name} ({lab})" for m, lab in zip(maps, labels)],
                             clock=k_time)
    rows = raw.shape[0]
    gaps = _fill_missing(raw, maps, labels, spec, where, place, notes) if options.missing == "repair" else {}

    # time grid first: it decides which rows stay
    if has_time:
        k = k_time
        if source.clock and (units[k].scale != 1.0 or units[k].offset != 0.0):
            raise DatasetError(f"{where}column time ({labels[k]}) holds clock readings ({source.clock}), read in "
                               f"seconds: drop the unit {units[k].text!r} from --column {maps[k].text!r}")
        ticks, wraps = (raw[:, k], None) if source.clock else unwrapped(raw[:, k])
        if wraps is not None:
            notes.append(wraps.note(f"time ({labels[k]})", units[k].text if not units[k].counts else "ticks"))
        t = units[k].convert(ticks)
        grid, keep = check_grid(t, where=where, label=f"time ({labels[k]})", place=place)
        t = t[keep] - t[keep][0]
    else:
        if rows < 2:
            raise DatasetError(f"{where}{rows} row(s); a record needs at least 2")
        grid, keep = regular_grid(rows, options.rate), np.ones(rows, dtype=bool)
        t = np.arange(rows) / options.rate
    notes += grid.notes()

    columns: dict[str, np.ndarray] = {"time": t}
    reports: list[ColumnReport] = []
    valid: dict[str, np.ndarray] = {}
    for i, (m, u) in enumerate(zip(maps, units)):
        if m.name == "time":
            reports.append(ColumnReport("time", labels[i], u, 0.0, float(t[-1]), missing=gaps.get("time")))
            continue
        kind, joint = column_kind(m.name, spec)
        found = None
        if kind in POSITION_KINDS:       # before saturation: a dropout to full scale is a glitch
            raw[:, i], found = _glitch_check(raw[:, i], options.glitches, where, f"column {m.name} ({labels[i]})", u,
                                             place, notes)
        sat = find_saturation(raw[:, i], u)
        report_sat = None
        if sat is not None:
            s, mask = sat
            report_sat = s
            notes.append(_saturation_note(m, labels[i], s, u, kind))
            if kind in MEASURED_KINDS:
                if options.saturation == "fail":
                    r = s.first_row
                    raise DatasetError(f"{where}column {m.name} ({labels[i]}): {place(r)}: "
                                       f"{raw[r - 1, i]:g} is at the converter's full scale ({s.converter}); "
                                       f"{s.samples} sample(s) in {s.runs} run(s) (--saturation fail)")
                valid[m.name] = ~mask[keep]
        v = u.convert(raw[:, i])
        if kind == "command":
            check_command_range(v, spec.joint(joint), where=where, label=f"{m.name} ({labels[i]})", place=place,
                                hint=f"; check the unit (--column {m.name}=SOURCE:V|mV|*SCALE+OFFSET)")
        if kind in ("angle", "position") and joint is not None:
            _note_outside_range(raw[:, i], v, m, u, spec, joint, notes)
        if kind == "pressure":
            fits = [] if u.counts else pressure_band.alternatives(raw[:, i], spec, u.text)
            why = pressure_band.implausible(v, spec, fits)
            if why is not None:
                notes.append(f"{m.name}: {why}: no chamber of the circuit holds that; check the unit ({u.text})"
                             + pressure_band.hint(fits, m.name, m.source))
        v = v[keep]
        columns[m.name] = v
        reports.append(ColumnReport(m.name, labels[i], u, float(v.min()), float(v.max()), report_sat, found,
                                    gaps.get(m.name)))
    order = dataset_order(columns, spec)
    ds = Dataset(order, np.column_stack([columns[c] for c in order]),
                 {r.name: r.unit.si for r in reports}, spec.name)
    reports.sort(key=lambda r: order.index(r.name))
    if not has_time:
        reports.insert(0, ColumnReport("time", f"--rate {options.rate:g} Hz", parse_unit(None, "time", column="time"),
                                       0.0, float(t[-1])))
    return ImportResult(str(path), spec.name, ds, reports, grid, notes, valid, options, [str(p) for p in paths])


def _fill_missing(raw: np.ndarray, maps: list[ColumnMap], labels: list[str], spec, where: str, place,
                  notes: list[str]) -> dict[str, Missing]:
    """Fill, in place, each column's runs of up to MAX_RUN missing samples (NaN in ``raw``): a time or
    measured column by interpolation, a command by the value before it (``ingest/missing.py``). A
    longer run, or a column with nothing in it, is an error naming the rows."""
    out = {}
    for i, m in enumerate(maps):
        gone = np.isnan(raw[:, i])
        if not gone.any():
            continue
        label = f"column {m.name} ({labels[i]})"
        if gone.all():
            raise DatasetError(f"{where}{label}: every sample is missing")
        found = runs(gone)
        a, b = max(found, key=lambda r: r[1] - r[0])
        if b - a + 1 > MAX_RUN:
            raise DatasetError(f"{where}{label}: {place(a + 1)} to {place(b + 1)}: {b - a + 1} missing samples in a row; "
                               f"--missing repair fills runs of up to {MAX_RUN} (a logger's missed reads), not a gap in "
                               f"the record: cut the file there, or read its parts separately")
        kind = "time" if m.name == "time" else column_kind(m.name, spec)[0]
        how = "carry" if kind == "time" else "hold" if kind == "command" else "line"
        raw[:, i] = filled(raw[:, i], how)
        gap = Missing(int(gone.sum()), [(a + 1, b + 1) for a, b in found],
                      "the value before" if how == "hold" else "interpolation")
        out[m.name] = gap
        notes.append(f"{label}: {gap.samples} missing sample(s) in {len(gap.runs)} run(s) (rows {gap.rows_text()}): "
                     f"filled by {gap.filled_by}" + (" (a command is held between its samples)" if how == "hold" else "")
                     + " (--missing repair)")
    return out


def _unit(m: ColumnMap, spec, source: "_Source | None") -> Unit:
    """The column's unit: as given, else as the file says (Parquet's metadata, a text table's row of
    units), else SI. Volts the file gives a sensed joint's position are the sensor's volts; a units
    row's cell that is no unit of the column is noted and the column read in SI."""
    kind, joint = column_kind(m.name, spec)
    text = m.unit if m.unit is not None else source.unit_of(source.names[source.resolve(m)]) if source.names else None
    sensor = None
    if joint is not None and kind in ("angle", "position"):
        js = spec.joint(joint)
        if js.sensed:
            s = js.components["sensor"]
            sensor = {"A": s["A"], "B": s["B"], "range": s["range"]}
    if m.unit is None and text == "V" and sensor is not None:
        text = SENSOR_VOLTS
    try:
        return parse_unit(text, kind, column=m.name, sensor=sensor)
    except ValueError as exc:
        if m.unit is None and text and source.unit_row:
            source.notes.append(f"column {m.name} ({source.label(m)}): the row of units says {text!r}, no unit of "
                                f"{KIND_TEXT[kind]}: read in {si_unit(kind)}; give its unit with --column "
                                f"{m.name}={m.source}:UNIT ({', '.join(allowed(kind, sensor is not None))})")
            return parse_unit(None, kind, column=m.name, sensor=sensor)
        raise DatasetError(f"--column {m.text!r}: {exc}") from None


def _note_outside_range(raw, v, m: ColumnMap, u: Unit, spec, joint: str, notes: list[str]) -> None:
    """A note where position samples ``v`` (SI, from ``raw`` in unit ``u``) lie outside the joint's
    range, with the units under which the raw values lie inside it."""
    tree = spec.tree
    i = tree.index(spec.joint(joint).dof)
    lo, hi = float(tree.lower[i]), float(tree.upper[i])
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return
    outside = joint_range.share(v, lo, hi)
    if outside > 0.0:
        kind = u.kind
        names = [n for n in allowed(kind, spec.joint(joint).sensed) if n != "*SCALE+OFFSET" and n != u.text]
        readings = {}
        for n in names:
            try:
                readings[n] = _unit(ColumnMap(m.name, m.source, n, m.text), spec, None)
            except DatasetError:
                continue
        fits = joint_range.readings_inside(raw, readings, lo, hi)
        hint = (" (read as " + " or ".join(f"{n} (--column {m.name}={m.source}:{n})" for n in fits)
                + " they lie inside it)") if fits else ""
        notes.append(f"{m.name}: {100 * outside:.3g} % of the samples lie more than {joint_range.MARGIN:g} {u.si} "
                     f"outside the joint's range [{lo:.4g}, {hi:.4g}] {u.si}: check the unit ({u.text}) and the sensor "
                     f"calibration{hint}")


def _glitch_check(raw: np.ndarray, policy: str, where: str, label: str, unit: Unit, place,
                  notes: list[str]) -> tuple[np.ndarray, Glitches | None]:
    """Find glitches in a measured position column (raw units); repair, keep or refuse them by ``policy``."""
    if policy == "keep":
        return raw, None
    hit = find_glitches(raw)
    if hit is None:
        return raw, None
    g, mask = hit
    raw_unit = "V" if unit.sensor_range is not None else "counts" if unit.counts else unit.text
    size = f"{abs(g.largest * unit.scale):.4g} {unit.si}" + (f" ({g.largest:.4g} {raw_unit})" if raw_unit != unit.si else "")
    rows = rows_text(g.rows, 8, g.runs)
    what = f"{label}: {g.samples} sample(s) in {g.runs} glitch(es) of 1 to 3 samples (rows {rows}), up to {size} off " \
           f"the samples either side" + (f", {g.largest / g.fastest_step:.3g} x the largest step between clean neighbouring " 
                                         f"samples" if g.fastest_step > 0 else "")
    if policy == "fail":
        raise DatasetError(f"{where}{label}: {place(g.first_row)}: a glitch: the position leaves the samples either "
                           f"side by {size} and comes back, faster than the joint moves anywhere else in the record "
                           f"({g.samples} such sample(s) in {g.runs} run(s); --glitches fail)")
    notes.append(what + "; a joint cannot move there and back that fast (a sensor or wiring fault): replaced by "
                 "interpolation between them (--glitches keep to keep them)")
    return repaired(raw, mask), g


def _saturation_note(m: ColumnMap, label: str, s: Saturation, u: Unit, kind: str) -> str:
    where = rows_text(s.rows, 5, s.runs)
    head = (f"{m.name} ({label}): {s.samples} sample(s) at the converter's full scale "
            f"({s.converter}: {s.full_scale[0]:g} / {s.full_scale[1]:g}), {s.runs} run(s), the longest "
            f"{s.longest_run} sample(s) (rows {where})")
    if kind == "command":
        return head + "; kept: the valve saw the saturated command"
    return head + "; the true value there is unknown: kept in the dataset, marked invalid (masked) in the import report"


class _Source:
    """The file behind an import: a text table or a Parquet file."""

    notes: list[str]
    names: list[str] | None
    n_fields: int
    clock: str | None = None        # after read: the time column's clock readings ('time of day', ...), if any

    def index(self, src: str | int, label: str) -> int:
        raise NotImplementedError

    def implicit_maps(self, maps: list[ColumnMap], spec, notes: list[str]) -> list[ColumnMap]:
        """Header columns named like dataset columns of ``spec`` and not mapped otherwise: taken as they are (SI).
        Resolves (checks) the sources of ``maps`` on the way."""
        used = {self.resolve(m) for m in maps}
        if self.names is None:
            return []
        targets = {m.name for m in maps}
        out = []
        for i, n in enumerate(self.names):
            if n in targets or i in used:
                if n in targets and i not in used:
                    notes.append(f"file column {n!r} not read: --column maps {n} from another column")
                continue
            try:
                column_kind(n, spec)
            except ValueError:
                continue
            out.append(ColumnMap(n, n, self.unit_of(n), f"{n}={n}"))
        ignored = [n for i, n in enumerate(self.names) if n and i not in used and n not in {m.name for m in out}
                   and n not in targets]
        if ignored and maps + out:
            notes.append(f"file columns not read: {', '.join(ignored[:12])}" + (", ..." if len(ignored) > 12 else ""))
        return out

    def unit_of(self, name: str) -> str | None:
        return None

    @property
    def unit_row(self) -> bool:
        """Whether the units the file gives come from a row of units under a text header (a guess at
        the columns' units, not metadata)."""
        return False

    def label(self, m: ColumnMap) -> str:
        """Where column ``m`` comes from, for reports and messages ("column 3", "header 'pos'")."""
        return m.source_label

    def line(self, row: int) -> int | None:
        """The file line of data row ``row`` (from 1), where the file has lines; after :meth:`read`."""
        return None

    def resolve(self, m: ColumnMap) -> int:
        path = self.path
        if isinstance(m.source, int):
            if m.source >= self.n_fields:
                raise DatasetError(f"{path}: --column {m.text!r}: column index {m.source} is out of range: the file has "
                                   f"{self.n_fields} column(s), 0..{self.n_fields - 1}")
            return m.source
        if self.names is None:
            raise DatasetError(f"{path}: --column {m.text!r}: the file has no header row, so {m.source!r} names no "
                               f"column; refer to columns by 0-based index (0..{self.n_fields - 1})")
        if m.source not in self.names:
            hint = ""
            if ":" in m.source:
                hint = f" ({m.source.rpartition(':')[2]!r} after ':' is not a unit)"
            raise DatasetError(f"{path}: --column {m.text!r}: no column {m.source!r} in the header{hint}; columns: "
                               f"{', '.join(self.names)}")
        return self.names.index(m.source)


class _TextSource(_Source):
    def __init__(self, path: Path, options: ReadOptions):
        self.path = path
        self.layout: TextLayout = open_text(path, header=False if options.no_header else None,
                                            delimiter=parse_delimiter(options.delimiter), skip_rows=options.skip_rows)
        self.notes = self.layout.notes
        self.names = self.layout.names
        self.n_fields = self.layout.n_columns
        self.missing = options.missing == "repair"

    def unit_of(self, name: str) -> str | None:
        units = self.layout.units
        return units[self.names.index(name)] or None if units else None

    @property
    def unit_row(self) -> bool:
        return self.layout.units is not None

    def read(self, sources, labels, clock=None):
        idx = [self.resolve(ColumnMap("", s, None, f"{lab}")) for s, lab in zip(sources, labels)]
        self._cols = read_columns(self.layout, idx, labels, cut_last_line=True, clock=clock, missing=self.missing)
        self.clock = self._cols.clock
        return self._cols.data, lambda r: f"row {r} (line {self.line(r)})"

    def line(self, row: int) -> int:
        return self._cols.line(row)


class _ParquetSource(_Source):
    def __init__(self, path: Path, options: ReadOptions):
        if options.no_header or options.delimiter is not None or options.skip_rows:
            raise DatasetError(f"{path}: --no-header, --delimiter and --skip-rows apply to text files, not Parquet")
        self.path = path
        self.table = ParquetTable(path)
        self.names = self.table.names
        self.n_fields = len(self.names)
        self.notes = []
        self.missing = options.missing == "repair"
        if self.table.rows == 0:
            raise DatasetError(f"{path}: no data rows")

    def unit_of(self, name: str) -> str | None:
        return self.table.units.get(name)

    def read(self, sources, labels, clock=None):
        idx = [self.resolve(ColumnMap("", s, None, f"{lab}")) for s, lab in zip(sources, labels)]
        data = self.table.columns([self.names[i] for i in idx], clock=clock, missing=self.missing)
        self.clock = self.table.clock_kind(self.names[idx[clock]]) if clock is not None else None
        if self.clock:
            self.notes.append(f"column {labels[clock]}: clock readings ({self.clock}), read as seconds from the first row")
        return data, (lambda r: f"row {r}")


class _JoinedSource(_Source):
    """Several files read side by side: row k of each is one sample; columns numbered on across files.
    A file without a header row contributes blank names (``names`` is None only when none has one)."""

    def __init__(self, paths: list[Path], options: ReadOptions):
        self.parts = [_open_source(p, options) for p in paths]
        self.path = Path(" + ".join(map(str, paths)))
        self.first = [0]                                  # global index of each part's column 0
        for part in self.parts:
            self.first.append(self.first[-1] + part.n_fields)
        self.n_fields = self.first[-1]
        named = any(part.names is not None for part in self.parts)
        self.names = [n for part in self.parts for n in (part.names or [""] * part.n_fields)] if named else None
        self._seen = [0] * len(self.parts)                # part notes already taken over
        self.notes = []
        self._take_notes()

    def _take_notes(self) -> None:
        for k, part in enumerate(self.parts):
            self.notes += [f"{part.path}: {n}" for n in part.notes[self._seen[k]:]]
            self._seen[k] = len(part.notes)

    def _part(self, index: int) -> tuple[int, int]:
        """(part, its own column index) of global column ``index``."""
        k = next(k for k in range(len(self.parts)) if index < self.first[k + 1])
        return k, index - self.first[k]

    def resolve(self, m: ColumnMap) -> int:
        if isinstance(m.source, str) and self.names is not None:
            hits = [i for i, n in enumerate(self.names) if n == m.source]
            if len(hits) > 1:
                files = ", ".join(str(self.parts[self._part(i)[0]].path) for i in hits)
                raise DatasetError(f"{self.path}: --column {m.text!r}: header {m.source!r} is in more than one file "
                                   f"({files}); refer to the column by its index ({', '.join(map(str, hits))})")
        if isinstance(m.source, str) and m.source not in (self.names or []):
            headers = "; ".join(f"{part.path}: {', '.join(part.names)}" if part.names else f"{part.path}: no header row"
                                for part in self.parts)
            raise DatasetError(f"{self.path}: --column {m.text!r}: no column {m.source!r} in the files' headers "
                               f"({headers}); a file without a header is read by 0-based index, numbered on across "
                               f"the files")
        if isinstance(m.source, int) and m.source >= self.n_fields:
            each = ", ".join(f"{part.path} {part.n_fields}" for part in self.parts)
            raise DatasetError(f"{self.path}: --column {m.text!r}: column index {m.source} is out of range: the files "
                               f"have {self.n_fields} column(s) together ({each}), numbered 0..{self.n_fields - 1} "
                               f"in the order given")
        return super().resolve(m)

    def label(self, m: ColumnMap) -> str:
        k, own = self._part(self.resolve(m))
        where = self.parts[k].path
        return f"header {m.source!r} in {where}" if isinstance(m.source, str) else f"column {m.source}: {where}'s column {own}"

    def unit_of(self, name: str) -> str | None:
        k, _ = self._part(self.names.index(name))
        return self.parts[k].unit_of(name)

    @property
    def unit_row(self) -> bool:
        return any(part.unit_row for part in self.parts)

    def read(self, sources, labels, clock=None):
        idx = [self.resolve(ColumnMap("", s, None, lab)) for s, lab in zip(sources, labels)]
        wanted: dict[int, list[int]] = {}                 # part -> positions in ``sources``
        for pos, i in enumerate(idx):
            wanted.setdefault(self._part(i)[0], []).append(pos)
        out: list[np.ndarray | None] = [None] * len(idx)
        rows = {}
        for k, positions in sorted(wanted.items()):
            own_clock = positions.index(clock) if clock in positions else None
            data, _ = self.parts[k].read([idx[p] - self.first[k] for p in positions], [labels[p] for p in positions],
                                         clock=own_clock)
            if own_clock is not None:
                self.clock = self.parts[k].clock
            rows[k] = data.shape[0]
            for j, p in enumerate(positions):
                out[p] = data[:, j]
        self._take_notes()
        unread = [str(self.parts[k].path) for k in range(len(self.parts)) if k not in wanted]
        if unread:
            self.notes.append(f"no column read from {', '.join(unread)}")
        if len(set(rows.values())) > 1:
            counts = ", ".join(f"{self.parts[k].path} {n}" for k, n in rows.items())
            raise DatasetError(f"{self.path}: files read side by side hold one sample per row each, but their rows "
                               f"differ ({counts}): cut them to the same samples")
        keys = sorted(wanted)

        def place(r: int) -> str:
            lines = [(self.parts[k].path, self.parts[k].line(r)) for k in keys if self.parts[k].line(r) is not None]
            if not lines:
                return f"row {r}"
            if len({ln for _, ln in lines}) == 1:
                return f"row {r} (line {lines[0][1]})"
            return f"row {r} (" + ", ".join(f"line {ln} of {path}" for path, ln in lines) + ")"
        return np.column_stack(out), place


def _open_source(path: Path, options: ReadOptions) -> _Source:
    if is_parquet(path):
        return _ParquetSource(path, options)
    return _TextSource(path, options)
