"""run_fleet: every record diagnosed once (unchanged ones skipped), on a backend, then the summary.

The driver (this process) checks what changed, reads each record as it submits it (a bad column fails
that record, naming the file), and writes each result as it comes: the record's files under
``DIR/<record>/``, the input key last, and fleet.json/fleet.csv every few seconds, so a run that is
stopped keeps what it finished and the next run does the rest. Everything is written again at the end,
index.html too.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Callable

from ..dataset import DatasetError
from .dates import DateError, iso, record_date
from .index_html import index_html
from .inputs import INPUT_FILE, changed_parts, input_key, options_digest, record_names, spec_digest, store_key, stored_key
from .progress import Progress, duration
from .rows import record_row
from .summary import fleet_data, write_summary
from .task import RecordJob, Shared, diagnose_record

SUMMARY_EVERY_S = 10.0      # fleet.json/csv rewritten at most this often while records finish (and at the end)
RECORD_FILES = ("diagnosis.json", "report.html", "report.md", "extended.toml", "error.txt", INPUT_FILE)


@dataclass
class FleetOptions:
    """What every record is diagnosed with (the options of ``hydrohil diagnose``)."""

    spec: object                       # configured robot spec
    read: object                       # ingest.ReadOptions
    initial_pose: str = "auto"
    effects: list[str] | None = None
    fmt: str = "html"
    date_from: str = "name"
    command_hold: str = "auto"         # diagnose --command-hold

    def digest(self) -> str:
        """What changes a diagnosis or its files (the date source changes neither)."""
        return options_digest({"reading": self.read.to_dict(), "initial_pose": self.initial_pose,
                               "effects": sorted(self.effects) if self.effects else None, "format": self.fmt,
                               "command_hold": self.command_hold})


@dataclass
class FleetResult:
    rows: list[dict]
    paths: dict[str, Path]
    wall_s: float
    backend: str | None
    outcomes: list = field(default_factory=list)     # backends.Outcome per record sent (item: its name; no files)

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if r["status"] == "failed"]


def _finish_text(row: dict) -> str:
    if row["status"] == "failed":
        return f"FAILED: {row['error']}"
    named = "; ".join(f"{e['label']} " + ", ".join(f"{k}={v:.4g}" for k, v in e["params"].items())
                      + "".join(f" (as well: {p} beyond its declared range)" for p in e.get("as_well_beyond_range", []))
                      for e in row["effects"])
    return f"{row['verdict']}" + (f": {named}" if named else "") + f" ({row['seconds']:.0f} s)"


def prismatic_joints(spec) -> frozenset[str]:
    from ..ingest.columns import PRISMATIC, joint_type

    return frozenset(j for j in spec.joint_names if joint_type(spec, j) == PRISMATIC)


def _clear(record_dir: Path) -> None:
    for name in RECORD_FILES:
        (record_dir / name).unlink(missing_ok=True)


def _plan(paths: list[Path], names: list[str], opts: FleetOptions, out_dir: Path):
    """Each record's date and input key; the unchanged ones get their stored row, the others are to do."""
    spec_hash, opt_hash = spec_digest(opts.spec), opts.digest()
    rows: list[dict | None] = [None] * len(paths)
    todo: list[tuple[int, dict, list[str]]] = []
    dates: list[str | None] = [None] * len(paths)
    notes: list[list[str]] = [[] for _ in paths]
    for i, (p, name) in enumerate(zip(paths, names)):
        try:
            dates[i] = iso(record_date(p, name, opts.date_from, opts.read))
        except (DateError, DatasetError, OSError) as exc:
            notes[i].append(f"no date: {exc}")
        try:
            key = input_key(p, spec_hash, opt_hash)
        except OSError as exc:
            rows[i] = record_row(name, str(p), dates[i], "failed", None, seconds=None, notes=notes[i],
                                 error=f"{p}: cannot be read ({exc.strerror or exc})")
            continue
        rdir = out_dir / name
        old = stored_key(rdir)
        report = "report.html" if opts.fmt == "html" else "report.md"
        diag = None
        if old and old.get("key") == key and all((rdir / f).is_file() for f in ("diagnosis.json", report, "extended.toml")):
            try:
                diag = json.loads((rdir / "diagnosis.json").read_text())
            except (OSError, ValueError):       # damaged since: diagnosed again
                old = None
        if diag is not None:
            rows[i] = record_row(name, str(p), dates[i], "unchanged", diag, seconds=old.get("seconds"),
                                 report=f"{name}/{report}", notes=notes[i])
        else:
            todo.append((i, key, changed_parts(old.get("key") if old else None, key)))
    return rows, todo, dates, notes


def run_fleet(records: list[str | Path], opts: FleetOptions, out_dir: str | Path, *,
              backend_factory: Callable[[], object], log: Callable[[str], None] = lambda msg: None) -> FleetResult:
    """Diagnose ``records`` into ``out_dir``; ``backend_factory`` is called only when a record needs it."""
    from ..identification.record import load_record

    t_start = time.perf_counter()
    paths = [Path(p) for p in records]
    seen: dict[Path, str] = {}
    for p in paths:
        r = p.resolve()
        if r in seen:
            raise ValueError(f"{p}: given twice (as {seen[r]})")
        seen[r] = str(p)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    names = record_names(paths)
    spec = opts.spec
    prismatic = prismatic_joints(spec)
    rows, todo, dates, notes = _plan(paths, names, opts, out_dir)
    unchanged = [r["record"] for r in rows if r is not None and r["status"] == "unchanged"]
    if unchanged:
        log(f"{len(unchanged)} record(s) unchanged since the last run, not diagnosed again: "
            + ", ".join(unchanged[:8]) + (" ..." if len(unchanged) > 8 else ""))
    backend = None
    outcomes = []
    generated = datetime.now().isoformat(timespec="seconds")

    def summary(final: bool) -> dict[str, Path]:
        done = [r if r is not None else record_row(names[i], str(paths[i]), dates[i], "failed", None, seconds=None,
                                                   error="not diagnosed: the run stopped before this record finished")
                for i, r in enumerate(rows)]
        data = fleet_data(done, robot=spec.name, backend=backend.describe() if backend else None, generated=generated,
                          wall_s=time.perf_counter() - t_start, prismatic=prismatic)
        out = write_summary(out_dir, data)
        if final:
            out["index"] = out_dir / "index.html"
            tmp = out_dir / "index.html.tmp"
            tmp.write_text(index_html(data))
            tmp.replace(out["index"])
        return out

    written: dict[str, Path] = {}
    outcomes_iter = None
    last_summary = [time.perf_counter()]
    try:
        if todo:
            backend = backend_factory()
            log(f"{len(todo)} record(s) to diagnose on {backend.describe()}")
            progress = Progress(len(todo), log)
            pending = {names[i]: (i, key, why) for i, key, why in todo}

            def fail(i: int, error: str, seconds: float | None = None, detail: str | None = None) -> None:
                rdir = out_dir / names[i]
                if rdir.is_dir():
                    _clear(rdir)
                if detail:
                    rdir.mkdir(parents=True, exist_ok=True)
                    (rdir / "error.txt").write_text(detail)
                rows[i] = record_row(names[i], str(paths[i]), dates[i], "failed", None, seconds=seconds, error=error,
                                     reason=pending[names[i]][2], notes=notes[i])

            def jobs():
                for i, key, why in todo:
                    try:
                        rec = load_record(paths[i], spec, initial_pose=opts.initial_pose, options=opts.read)
                    except (DatasetError, ValueError, OSError) as exc:
                        fail(i, str(exc))
                        progress.started(names[i])
                        progress.finished(names[i], _finish_text(rows[i]))
                        continue
                    progress.started(names[i])
                    yield RecordJob(names[i], rec)

            shared = Shared(spec, opts.effects, opts.fmt, opts.command_hold)
            outcomes_iter = backend.map(diagnose_record, shared, jobs())
            for o in outcomes_iter:
                name = o.item.name
                i, key, why = pending[name]
                v = o.value
                outcomes.append(o)
                o.item = name                  # what the caller keeps: timings, not records and files
                o.value = {k: x for k, x in v.items() if k != "files"} if v else v
                if o.error is not None:
                    fail(i, f"{type(o.error).__name__}: {o.error}", o.seconds)
                elif not v["ok"]:
                    fail(i, v["error"], v["seconds"], v.get("traceback"))
                else:
                    rdir = out_dir / name
                    rdir.mkdir(parents=True, exist_ok=True)
                    _clear(rdir)
                    for fname, data in v["files"].items():
                        (rdir / fname).write_bytes(data)
                    store_key(rdir, {"key": key, "source": str(paths[i]), "seconds": round(v["seconds"], 2),
                                     "finished": datetime.now().isoformat(timespec="seconds")})
                    diag = json.loads(v["files"]["diagnosis.json"])
                    report = "report.html" if "report.html" in v["files"] else "report.md"
                    rows[i] = record_row(name, str(paths[i]), dates[i], "diagnosed", diag, seconds=v["seconds"],
                                         report=f"{name}/{report}", reason=why, notes=notes[i])
                progress.finished(name, _finish_text(rows[i]))
                if time.perf_counter() - last_summary[0] >= SUMMARY_EVERY_S:
                    summary(final=False)
                    last_summary[0] = time.perf_counter()
    finally:
        if outcomes_iter is not None:
            outcomes_iter.close()          # tasks still in flight are cancelled
        if backend is not None:
            backend.close()
        written = summary(final=True)
    wall = time.perf_counter() - t_start
    done = [r for r in rows if r is not None]
    n_diag = sum(r["status"] == "diagnosed" for r in done)
    n_fail = sum(r["status"] == "failed" for r in done)
    log(f"{n_diag} diagnosed, {len(unchanged)} unchanged, {n_fail} failed in {duration(wall)}"
        + (f" ({n_diag / wall * 3600:.0f} records per hour)" if n_diag else ""))
    return FleetResult([r for r in rows if r is not None], written, wall, backend.describe() if backend else None, outcomes)

