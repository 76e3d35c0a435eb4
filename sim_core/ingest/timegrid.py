"""The time grid of a measured record: jitter, gaps and repeated timestamps are reported and the real
grid is kept; time going backwards is an error naming the row.

Repeated timestamps: the later rows of a run of equal timestamps are dropped and the first kept
(a logger that writes a sample twice, or a clock that did not tick), and the count is reported.
A gap is an interval longer than ``GAP_FACTOR`` median periods (missing samples); jitter is the
spread of the other intervals around the median period. A grid coarser than ``SLOW_RATE_HZ`` is noted
with the time unit that would give a usable one (:func:`unit_hint`): a logger's milliseconds read as
seconds make a 50 Hz record a 0.05 Hz one that lasts hours.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

GAP_FACTOR = 1.5
JITTER_NOTE_PCT = 0.1     # below this rms jitter (% of the period) the grid is called regular
# Hz: the coarsest grid fit and diagnose accept. The valve's command is replayed held from one sample
# to the next, and what the model's effects do (spool lag, delay, friction, compliance) happens within
# 0.01-0.1 s: samples farther apart than 0.2 s cannot show it
SLOW_RATE_HZ = 5.0


def unit_hint(median_period_s: float) -> str:
    """What a median period too long for a record of a moving joint most likely is, and the
    ``--column`` unit that reads it so: milliseconds or microseconds counted as seconds."""
    for unit, factor, name in ((":ms", 1e-3, "milliseconds"), (":*1e-6", 1e-6, "microseconds")):
        period = median_period_s * factor
        if period <= 1.0 / SLOW_RATE_HZ:
            return (f"if the time column counts {name}, read it with --column time=SOURCE{unit} (a sample every "
                    f"{1e3 * period:.4g} ms, {1.0 / period:.4g} Hz)")
    return "check the time column's unit"


FAST_RATE_HZ = 1e4      # no hydraulic rig's logger samples faster: a time column read too short beyond it


def short_hint(median_period_s: float, duration_s: float, min_duration_s: float) -> str:
    """What a record too short to identify may be: a time column counting minutes or hours read as
    seconds, each where that reading gives at least ``min_duration_s`` at a logger's rate; else ''."""
    out = ""
    for unit, factor, name in ((":*60", 60.0, "minutes"), (":*3600", 3600.0, "hours")):
        period, duration = median_period_s * factor, duration_s * factor
        if duration >= min_duration_s and SLOW_RATE_HZ <= 1.0 / period <= FAST_RATE_HZ:
            out += (f"; if the time column counts {name}, read it with --column time=SOURCE{unit} (a sample every "
                    f"{1e3 * period:.4g} ms, {1.0 / period:.4g} Hz, {duration:.4g} s)")
    return out


@dataclass
class TimeGrid:
    """What the time column looked like (figures in s and % of the median period)."""

    source: str                       # 'column' or 'rate'
    rows: int                         # rows kept
    median_period_s: float
    rate_hz: float
    duration_s: float
    jitter_rms_pct: float = 0.0       # rms deviation of the non-gap intervals from the median period
    jitter_max_pct: float = 0.0       # largest such deviation
    gaps: int = 0                     # intervals > GAP_FACTOR median periods
    largest_gap_s: float = 0.0
    missing_samples: int = 0          # estimated from the gaps
    repeated: int = 0                 # rows dropped for a repeated timestamp
    repeated_rows: list[int] = field(default_factory=list)   # first few dropped rows (from 1)
    start_s: float = 0.0              # first timestamp before the grid was shifted to start at 0

    def to_dict(self) -> dict:
        return asdict(self)

    def notes(self) -> list[str]:
        out = []
        if self.source == "rate":
            out.append(f"time: no time column; a regular grid at {self.rate_hz:g} Hz (--rate)")
            if self.rate_hz < SLOW_RATE_HZ:
                out.append(f"time: {self.rate_hz:g} Hz is below the {SLOW_RATE_HZ:g} Hz fit and diagnose need: check --rate")
            return out
        if self.rate_hz < SLOW_RATE_HZ:
            out.append(f"time: a sample every {self.median_period_s:.4g} s ({self.rate_hz:.3g} Hz) is below the "
                       f"{SLOW_RATE_HZ:g} Hz fit and diagnose need; {unit_hint(self.median_period_s)}")
        if self.jitter_rms_pct >= JITTER_NOTE_PCT:
            out.append(f"time: jitter {self.jitter_rms_pct:.2g} % rms (largest {self.jitter_max_pct:.2g} %) of the "
                       f"{1e3 * self.median_period_s:.4g} ms median period; the real timestamps are kept")
        if self.gaps:
            out.append(f"time: {self.gaps} gap(s) longer than {GAP_FACTOR:g} periods, the largest {self.largest_gap_s:.4g} s "
                       f"(about {self.missing_samples} missing sample(s) in all); kept as recorded")
        if self.repeated:
            rows = ", ".join(str(r) for r in self.repeated_rows) + (", ..." if self.repeated > len(self.repeated_rows) else "")
            out.append(f"time: {self.repeated} row(s) repeat the previous timestamp and were dropped, the first of "
                       f"each kept (rows {rows})")
        if self.start_s:
            out.append(f"time: starts at {self.start_s:.10g} s in the file; shifted to start at 0")
        return out


def regular_deviations(periods: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(median period, mask of the gaps: intervals longer than GAP_FACTOR median periods, deviations
    (s) of the other intervals from the median): what the jitter is measured on."""
    med = float(np.median(periods))
    gap = periods > GAP_FACTOR * med
    return med, gap, periods[~gap] - med


def check_grid(t: np.ndarray, *, where: str, label: str, place) -> tuple[TimeGrid, np.ndarray]:
    """Check a time column (s) in file order. Returns the grid report and the mask of rows to keep.
    ``place(row)`` names data row ``row`` (from 1) in messages: 'row 12 (line 13)'."""
    from ..dataset import DatasetError

    if t.size < 2:
        raise DatasetError(f"{where}column {label}: {t.size} row(s); a record needs at least 2")
    d = np.diff(t)
    back = np.flatnonzero(d < 0)
    if back.size:
        r = int(back[0]) + 2
        step = float(np.median(d[: r - 2])) if r > 2 else 0.0
        restart = ""
        if r > 3 and t[r - 1] <= t[0] + 2.0 * step:      # back to where the file began: a logger restarted
            restart = (f"; a second run seems to start there (time back to {t[r - 1]:.10g} s, the file began at "
                       f"{t[0]:.10g} s): split the file before {place(r)} and read each run on its own (one as "
                       f"--validation)")
        raise DatasetError(
            f"{where}column {label}: {place(r)}: time goes backwards, {t[r - 1]:.10g} s after "
            f"{t[r - 2]:.10g} s in {place(r - 1)}; time must increase{restart}"
        )
    keep = np.ones(t.size, dtype=bool)
    keep[1:] = d > 0
    dropped = np.flatnonzero(~keep) + 1
    tk = t[keep]
    if tk.size < 2:
        raise DatasetError(f"{where}column {label}: every timestamp is the same ({t[0]:g} s)")
    dk = np.diff(tk)
    med, gap, dev_s = regular_deviations(dk)
    dev = dev_s / med * 100.0 if dev_s.size else np.zeros(1)
    grid = TimeGrid(
        source="column", rows=int(tk.size), median_period_s=med, rate_hz=1.0 / med,
        duration_s=float(tk[-1] - tk[0]),
        jitter_rms_pct=float(np.sqrt(np.mean(dev ** 2))), jitter_max_pct=float(np.max(np.abs(dev))),
        gaps=int(gap.sum()), largest_gap_s=float(dk[gap].max()) if gap.any() else 0.0,
        missing_samples=int(np.sum(np.rint(dk[gap] / med) - 1)) if gap.any() else 0,
        repeated=int(dropped.size), repeated_rows=[int(r) for r in dropped[:5]], start_s=float(tk[0]),
    )
    return grid, keep


def regular_grid(rows: int, rate: float) -> TimeGrid:
    period = 1.0 / rate
    return TimeGrid(source="rate", rows=rows, median_period_s=period, rate_hz=rate, duration_s=(rows - 1) * period)
