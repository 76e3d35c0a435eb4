"""Time columns written as clock readings, as many loggers do (LabVIEW, PLC and spreadsheet exports):
an ISO 8601 date and time (``2026-11-26 12:03:45.120``, ``T`` between them, a ``Z`` or ``+01:00``
zone) or a time of day (``12:03:45.120``, ``9:05:00``). Read as seconds; the importer then counts
them from the first row. A time of day that passes midnight starts again at 0: where it falls back
by more than half a day from one row to the next, a day is added from there on.
"""

from __future__ import annotations

import re
from datetime import datetime, timezone

import numpy as np

TIME_OF_DAY = re.compile(r"^(\d{1,2}):(\d{2}):(\d{2}(?:[.,]\d+)?)$")
DATE_TIME = re.compile(r"^\d{4}-\d{2}-\d{2}[T ]\d{1,2}:\d{2}(:\d{2}([.,]\d+)?)?(Z|[+-]\d{2}:?\d{2})?$")
_EPOCH = datetime(1970, 1, 1)
DAY_S = 86400.0


def kind(cell: str) -> str | None:
    """'date and time', 'time of day', or None when ``cell`` is neither."""
    r = reading(cell)
    return None if r is None else r[0]


def seconds(cell: str, since: int = 0) -> float | None:
    """Seconds of a clock reading after ``since`` (whole seconds on the same scale: subtracted exactly,
    before the fraction is added, so that a date and time keeps its microseconds in float64): since
    midnight for a time of day, since 1970-01-01 for a date and time (in its zone's UTC when it gives
    one, else as written); None when ``cell`` is not one."""
    r = reading(cell)
    return None if r is None else seconds_of(r, since)


def seconds_of(r: tuple[str, int, float], since: int = 0) -> float:
    """``seconds`` of a ``reading``: whole seconds since ``since`` first, then the fraction."""
    return (r[1] - since) + r[2]


def whole_seconds(cell: str) -> int | None:
    """The whole seconds of a clock reading (``seconds``' scale), None when ``cell`` is not one."""
    r = reading(cell)
    return None if r is None else r[1]


def reading(cell: str) -> tuple[str, int, float] | None:
    """(kind, whole seconds, fraction of a second) of a clock reading, parsed once; None when
    ``cell`` is not one (``seconds`` says on which scale)."""
    s = cell.strip().strip('"')
    m = TIME_OF_DAY.match(s)
    if m:
        h, mi, sec = int(m.group(1)), int(m.group(2)), m.group(3).replace(",", ".")
        whole, _, frac = sec.partition(".")
        if h > 23 or mi > 59 or int(whole) > 60:
            return None
        return "time of day", h * 3600 + mi * 60 + int(whole), float("0." + frac) if frac else 0.0
    if not DATE_TIME.match(s):
        return None
    frac = re.search(r"[.,](\d+)", s[10:])
    whole = s if frac is None else s[:10] + s[10:].replace(frac.group(0), "", 1)
    try:
        dt = datetime.fromisoformat(whole.replace("Z", "+00:00"))
    except ValueError:
        return None
    if dt.tzinfo is not None:
        dt = dt.astimezone(timezone.utc).replace(tzinfo=None)
    delta = dt - _EPOCH
    return "date and time", delta.days * 86400 + delta.seconds, float("0." + frac.group(1)) if frac else 0.0


def past_midnight(t: np.ndarray) -> tuple[np.ndarray, int]:
    """A time-of-day column with a day added wherever it falls back by more than half a day (the
    clock passed midnight); returns the times and how many midnights were passed."""
    back = np.flatnonzero(np.diff(t) < -DAY_S / 2)
    if back.size == 0:
        return t, 0
    step = np.zeros(t.size)
    step[back + 1] = DAY_S
    return t + np.cumsum(step), int(back.size)
