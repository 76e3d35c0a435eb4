"""Recordings: every tick's row, drained from the engine's shared ring into a dataset file.

The engine writes one row per tick while recording and publishes the row count after the row
(release store). A thread here drains the ring 20 times a second into the file: the dataset CSV of
``hydrohil simulate``, or Parquet (one float64 column per dataset column, the same names; schema
metadata ``hydrohil.units`` = JSON {column: unit} and ``hydrohil.robot``). Stopping asks the engine
for the final row count and drains up to it, so a clean stop (also on SIGTERM) leaves a complete
file: one row per tick, none missing, none twice. When the engine dies, the recording is closed at
once with every row the engine published and the reason (``stop_reason``). If the drain ever fell a
whole ring behind, the recording is marked incomplete instead of silently losing ticks.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import re
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .engine import atomics as A
from .engine import shared as S

log = logging.getLogger("hydrohil.recorder")

FORMATS = {"csv": ("csv", "text/csv"), "parquet": ("parquet", "application/vnd.apache.parquet")}


class CsvRows:
    """The dataset CSV of ``hydrohil simulate``: a header, then one line per row."""

    def __init__(self, path: Path, columns: list[str], spec):
        self._fh = open(path, "w", buffering=1 << 20)
        self._fh.write(",".join(columns) + "\n")

    def write(self, rows: np.ndarray) -> None:
        np.savetxt(self._fh, rows, delimiter=",", fmt="%.10g")

    def close(self, reason: str) -> None:
        self._fh.flush()
        self._fh.close()


class ParquetRows:
    """Parquet, written in row groups of ``GROUP_ROWS`` rows; the footer (with the stop reason in the
    file's key-value metadata) is written when the recording closes."""

    GROUP_ROWS = 10000

    def __init__(self, path: Path, columns: list[str], spec):
        import pyarrow as pa
        import pyarrow.parquet as pq

        from sim_core.dataset import dataset_units

        self._pa = pa
        meta = {b"hydrohil.units": json.dumps(dataset_units(columns, spec)).encode(),
                b"hydrohil.robot": spec.name.encode()}
        self.schema = pa.schema([pa.field(c, pa.float64()) for c in columns], metadata=meta)
        self._writer = pq.ParquetWriter(str(path), self.schema)
        self._pending: list[np.ndarray] = []
        self._n = 0

    def write(self, rows: np.ndarray) -> None:
        self._pending.append(np.array(rows, dtype=np.float64))
        self._n += len(rows)
        if self._n >= self.GROUP_ROWS:
            self._flush()

    def _flush(self) -> None:
        if not self._pending:
            return
        block = np.concatenate(self._pending)
        self._pending, self._n = [], 0
        arrays = [self._pa.array(block[:, k]) for k in range(block.shape[1])]
        self._writer.write_table(self._pa.Table.from_arrays(arrays, schema=self.schema))

    def close(self, reason: str) -> None:
        self._flush()
        self._writer.add_key_value_metadata({"hydrohil.stop_reason": reason})
        self._writer.close()


WRITERS = {"csv": CsvRows, "parquet": ParquetRows}


@dataclass
class Recording:
    id: str
    path: Path
    format: str
    started_at: str
    rows: int = 0
    active: bool = True
    complete: bool = True
    error: str = ""
    stop_reason: str = ""
    first_tick: int | None = None
    last_tick: int | None = None

    @property
    def media_type(self) -> str:
        return FORMATS[self.format][1]

    def describe(self) -> dict:
        return {"id": self.id, "file": self.path.name, "format": self.format, "started_at": self.started_at,
                "rows": self.rows, "active": self.active, "complete": self.complete, "error": self.error or None,
                "stop_reason": self.stop_reason or None}


class Recorder:
    def __init__(self, block: S.SharedBlock, spec, directory: Path, engine):
        self.block = block
        self.spec = spec
        self.engine = engine             # request(op, *args): the supervisor
        self.dir = Path(directory)
        self.columns = (["time"] + [f"u_{j}" for j in spec.joint_names] + [f"q_{j}" for j in spec.sensed_joints]
                        + [f"p_{j}_a" for j in spec.joint_names] + [f"p_{j}_b" for j in spec.joint_names])
        self.recordings: dict[str, Recording] = {}
        self.current: Recording | None = None
        self._lock = threading.Lock()
        self._stop_evt = threading.Event()
        self._thread: threading.Thread | None = None
        self._writer = None
        self._drained = 0

    def start(self, name: str | None = None, fmt: str = "csv") -> Recording:
        if fmt not in FORMATS:
            raise ValueError(f"recording format {fmt!r}: one of {', '.join(FORMATS)}")
        with self._lock:
            if self.current is not None:
                raise RuntimeError(f"recording {self.current.id} is already running")
            self.dir.mkdir(parents=True, exist_ok=True)
            stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S-%f")
            rid = re.sub(r"[^A-Za-z0-9_.-]", "_", name) if name else f"rec-{stamp}"
            if rid in self.recordings:
                raise RuntimeError(f"a recording named {rid!r} exists")
            rec = Recording(rid, self.dir / f"{rid}.{FORMATS[fmt][0]}", fmt, stamp)
            self._writer = WRITERS[fmt](rec.path, self.columns, self.spec)
            self._drained = 0
            try:
                self.engine.request("record", True)
            except Exception:
                self._writer.close("the engine refused to record")
                rec.path.unlink(missing_ok=True)
                self._writer = None
                raise
            self.current = rec
            self.recordings[rid] = rec
            self._stop_evt.clear()
            self._thread = threading.Thread(target=self._drain_loop, name="hydrohil-recorder", daemon=True)
            self._thread.start()
            return rec

    def stop(self) -> Recording:
        """Clean stop: the engine stops recording and says how many rows it wrote; all of them go to
        the file."""
        with self._lock:
            rec = self.current
            if rec is None:
                raise RuntimeError("no recording is running")
            self._stop_evt.set()
            self._thread.join(5.0)
            reason = "stopped"
            try:
                final = int(self.engine.request("record", False)["rows"])
            except Exception as exc:  # noqa: BLE001 - engine gone: keep what it published
                final = self.block.rec_rows()
                reason = f"engine stopped before the recording ({exc})"
                rec.error = reason
            return self._close(rec, final, reason)

    def abort(self, reason: str) -> Recording | None:
        """The engine died: close the running recording now with every row it published."""
        with self._lock:
            rec = self.current
            if rec is None:
                return None
            self._stop_evt.set()
            self._thread.join(5.0)
            return self._close(rec, self.block.rec_rows(), reason)

    def _close(self, rec: Recording, final: int, reason: str) -> Recording:
        self._drain(final)
        rec.stop_reason = reason
        self._writer.close(reason)
        self._writer = None
        rec.active = False
        self.current = None
        log.info("recording %s closed: %d rows, %s (%s)", rec.id, rec.rows, "complete" if rec.complete else "INCOMPLETE",
                 reason)
        return rec

    def _drain_loop(self) -> None:
        while not self._stop_evt.wait(0.05):
            self._drain(self.block.rec_rows())

    def _drain(self, upto: int) -> None:
        rec = self.current
        if rec is None or upto <= self._drained:
            return
        cap = self.block.rec.shape[0]
        if upto - self._drained > cap:
            rec.complete = False
            rec.error = f"{upto - self._drained - cap} ticks were lost (recorder fell a full ring behind)"
            self._drained = upto - cap
        idx = np.arange(self._drained, upto) % cap
        rows = self.block.rec[idx]
        A.fence_acquire()   # the copy above happens before the count below is read
        if self.block.rec_rows() - cap > self._drained:   # the engine overwrote rows while they were copied
            rec.complete = False
            rec.error = "rows were overwritten while being read (recorder fell a full ring behind)"
        ticks = rows[:, -1]
        if rec.first_tick is None and len(ticks):
            rec.first_tick = int(ticks[0])
        elif len(ticks) and rec.last_tick is not None and ticks[0] != rec.last_tick + 1:
            rec.complete = False
            rec.error = f"tick gap before tick {int(ticks[0])}"
        if len(ticks):
            rec.last_tick = int(ticks[-1])
        self._writer.write(rows[:, :-1])
        rec.rows += len(rows)
        self._drained = upto

    def close(self) -> None:
        if self.current is not None:
            self.stop()

    def get(self, rid: str) -> Recording:
        try:
            return self.recordings[rid]
        except KeyError:
            raise KeyError(f"no recording {rid!r}") from None
