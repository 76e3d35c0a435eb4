"""Missing samples: a logger that times out on a read (a sensor's bus, a dropped CAN frame) writes an
empty cell or NaN for that sample and goes on.

``--missing fail`` (default) refuses the first one, naming the column and row. ``--missing repair``
fills runs of up to ``MAX_RUN`` samples of a column: a measured position or pressure and the time
by the line between the samples either side (at the record's first or last rows, the nearest sample's
value; a time, the nearest period carried on), a command by the value before it (what the valve
went on receiving: a controller's output is held between its samples). A longer run is a gap in the
record, not a missed read: refused, with where it is. Every filled sample is reported by column and row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .runs import bridged, rows_text

MAX_RUN = 3        # samples in a row: more is a gap in the record, not a logger's missed read
POLICIES = ("fail", "repair")
# cells a logger writes for a sample it did not get (compared lower-case and stripped); "inf" is not
# one: an overflow is a converter at its full scale
TOKENS = frozenset({"", "nan", "-nan", "+nan", "na", "n/a", "#n/a", "null", "none"})
HINT = f"--missing repair fills runs of up to {MAX_RUN} missing samples"


def is_missing(cell: str) -> bool:
    """Whether a text cell holds no sample (empty, NaN or a spreadsheet's #N/A)."""
    return cell.strip().lower() in TOKENS


@dataclass
class Missing:
    """The missing samples of one column and how they were filled."""

    samples: int
    runs: list[tuple[int, int]]       # (first, last) data rows, 1-based, of each run
    filled_by: str                    # 'interpolation' or 'the value before' (a command)

    def to_dict(self) -> dict:
        return {"samples": self.samples, "runs": [list(r) for r in self.runs], "filled_by": self.filled_by}

    def rows_text(self, most: int = 8) -> str:
        return rows_text(self.runs, most)


def filled(y: np.ndarray, how: str) -> np.ndarray:
    """``y`` with its NaN samples filled: 'line' (between the samples either side; the nearest at the
    ends), 'carry' (a time: the line, and at the ends the nearest period carried on) or 'hold' (the
    value before; at the start, the first sample's)."""
    gone = np.isnan(y)
    k = np.arange(y.size)
    have = np.flatnonzero(~gone)
    if how == "hold":
        out = y.copy()
        last = np.maximum.accumulate(np.where(gone, -1, k))
        out[gone] = np.where(last[gone] >= 0, y[np.maximum(last[gone], 0)], y[have[0]])
        return out
    out = bridged(y, gone)                                  # the nearest sample's value beyond the ends
    if how == "carry" and have.size >= 2:
        head, tail = k[gone & (k < have[0])], k[gone & (k > have[-1])]
        out[head] = y[have[0]] - (have[0] - head) * (y[have[1]] - y[have[0]]) / (have[1] - have[0])
        out[tail] = y[have[-1]] + (tail - have[-1]) * (y[have[-1]] - y[have[-2]]) / (have[-1] - have[-2])
    return out
