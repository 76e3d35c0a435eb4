"""Recordings: every tick's row, drained from the engine's shared ring into a dataset CSV.

The engine writes one row per tick while recording; a thread here drains the ring 20 times a
second into the CSV (the format of ``hydrohil simulate``). Stopping asks the engine for the final
row count and drains up to it, so a clean stop (also on SIGTERM) leaves a complete file: one row per
tick, none missing, none twice. If the drain ever fell a whole ring behind, the recording is marked
incomplete instead of silently losing ticks.
"""

from __future__ import annotations

import datetime as dt
import re
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .engine import shared as S


@dataclass
class Recording:
    id: str
    path: Path
    started_at: str
    rows: int = 0
    active: bool = True
    complete: bool = True
    error: str = ""
    first_tick: int | None = None
    last_tick: int | None = None

    def describe(self) -> dict:
        return {"id": self.id, "file": self.path.name, "started_at": self.started_at, "rows": self.rows,
                "active": self.active, "complete": self.complete, "error": self.error or None}


class Recorder:
    def __init__(self, block: S.SharedBlock, spec, directory: Path, engine):
        self.block = block
        self.engine = engine
        self.dir = Path(directory)
        self.columns = (["time"] + [f"u_{j}" for j in spec.joint_names] + [f"q_{j}" for j in spec.sensed_joints]
                        + [f"p_{j}_a" for j in spec.joint_names] + [f"p_{j}_b" for j in spec.joint_names])
        self.recordings: dict[str, Recording] = {}
        self.current: Recording | None = None
        self._lock = threading.Lock()
        self._stop_evt = threading.Event()
        self._thread: threading.Thread | None = None
        self._fh = None
        self._drained = 0

    def start(self, name: str | None = None) -> Recording:
        with self._lock:
            if self.current is not None:
                raise RuntimeError(f"recording {self.current.id} is already running")
            self.dir.mkdir(parents=True, exist_ok=True)
            stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S-%f")
            rid = re.sub(r"[^A-Za-z0-9_.-]", "_", name) if name else f"rec-{stamp}"
            if rid in self.recordings:
                raise RuntimeError(f"a recording named {rid!r} exists")
            rec = Recording(rid, self.dir / f"{rid}.csv", stamp)
            self._fh = open(rec.path, "w", buffering=1 << 20)
            self._fh.write(",".join(self.columns) + "\n")
            self._drained = 0
            self.current = rec
            self.recordings[rid] = rec
            self.engine.request("record", True)
            self._stop_evt.clear()
            self._thread = threading.Thread(target=self._drain_loop, name="hydrohil-recorder", daemon=True)
            self._thread.start()
            return rec

    def stop(self) -> Recording:
        with self._lock:
            rec = self.current
            if rec is None:
                raise RuntimeError("no recording is running")
            self._stop_evt.set()
            self._thread.join(5.0)
            try:
                final = int(self.engine.request("record", False)["rows"])
            except Exception as exc:  # engine gone: keep what reached the ring
                final = int(self.block.rec_hdr[S.R_ROWS])
                rec.error = f"engine stopped before the recording ({exc})"
            self._drain(final)
            self._fh.flush()
            self._fh.close()
            self._fh = None
            rec.active = False
            self.current = None
            return rec

    def _drain_loop(self) -> None:
        while not self._stop_evt.wait(0.05):
            self._drain(int(self.block.rec_hdr[S.R_ROWS]))

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
        ticks = rows[:, -1]
        if rec.first_tick is None and len(ticks):
            rec.first_tick = int(ticks[0])
        elif len(ticks) and rec.last_tick is not None and ticks[0] != rec.last_tick + 1:
            rec.complete = False
            rec.error = f"tick gap before tick {int(ticks[0])}"
        if len(ticks):
            rec.last_tick = int(ticks[-1])
        np.savetxt(self._fh, rows[:, :-1], delimiter=",", fmt="%.10g")
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
