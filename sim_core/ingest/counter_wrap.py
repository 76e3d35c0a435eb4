"""A time column that is a logger's tick counter wrapping around: a PLC's 16-bit millisecond counter
runs from 0 to 65535 and starts again at 0 every 65.5 s, a 32-bit microsecond one every 71.6 min.
Read as time, it goes backwards at each wrap.

A drop is a wrap when the counter's values all lie in an n-bit range (unsigned, or signed around 0)
and, with 2**n added, the step across the drop is a sample period (at most ``MAX_STEPS`` median
periods: a sample or two lost at the wrap too). Any other drop stays time going backwards, an error
the time check names (a second run appended to the file, a clock set back); the rows after it are
counted from their own start, so that check still sees a second run begin where it does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BITS = (8, 16, 24, 32)      # counter widths loggers use
MAX_STEPS = 3.0             # the step across a wrap, in median periods


@dataclass
class Wraps:
    bits: int
    rows: list[int]         # data rows (from 1) where the counter starts again

    def note(self, label: str, unit: str) -> str:
        rows = ", ".join(map(str, self.rows[:8])) + (", ..." if len(self.rows) > 8 else "")
        return (f"column {label}: a {self.bits}-bit counter that starts again after {2 ** self.bits - 1} {unit} "
                f"({len(self.rows)} time(s), rows {rows}): unwrapped, {2 ** self.bits} {unit} added at each")


def unwrapped(raw: np.ndarray) -> tuple[np.ndarray, Wraps | None]:
    """``raw`` (a time column in its logged unit) with a wrapping counter's wraps undone, and where they
    were; ``raw`` itself and None when it does not wrap."""
    d = np.diff(raw)
    back = d < 0
    if not back.any() or not (d > 0).any():
        return raw, None
    step = float(np.median(d[d > 0]))
    lo, hi = float(raw.min()), float(raw.max())
    for bits in BITS:
        span = float(2 ** bits)
        if not (0.0 <= lo and hi < span or -span / 2 <= lo and hi < span / 2):
            continue
        drops = np.flatnonzero(back)
        across = d[drops] + span
        wrap = (across > 0.0) & (across <= MAX_STEPS * step)
        if not wrap.any():
            return raw, None        # within this width but no wrap of it: no wider counter explains a drop either
        out = np.asarray(raw, dtype=float).copy()
        added = 0.0
        for i, is_wrap, end in zip(drops, wrap, list(drops[1:] + 1) + [raw.size]):
            added = added + span if is_wrap else 0.0     # another drop: a new run from its own start
            out[i + 1:end] += added
        return out, Wraps(bits, [int(i) + 2 for i in drops[wrap]])
    return raw, None
