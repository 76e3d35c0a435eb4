"""Runs of flagged samples in a column (at full scale, glitched, missing, masked) and the line that
bridges them: what saturation, glitch and missing-sample checks each report and repair."""

from __future__ import annotations

import numpy as np


def runs(flagged: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) 0-based indices of each run of True in ``flagged``."""
    edges = np.diff(np.concatenate(([0], np.asarray(flagged).astype(np.int8), [0])))
    return [(int(a), int(b) - 1) for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]


def rows_text(rows: list[tuple[int, int]], most: int, total: int | None = None) -> str:
    """The first ``most`` of ``rows`` ((first, last) runs) as '12, 40-42', with ', ...' where there are
    more (``total`` runs in all; default: as many as given)."""
    text = ", ".join(f"{a}-{b}" if b > a else str(a) for a, b in rows[:most])
    return text + (", ..." if (len(rows) if total is None else total) > most else "")


def bridged(y: np.ndarray, flagged: np.ndarray) -> np.ndarray:
    """``y`` with the samples under ``flagged`` replaced by the line between the unflagged samples either
    side (the nearest unflagged sample at an end of the record)."""
    y = np.asarray(y, dtype=float).copy()
    if flagged.any() and not flagged.all():
        idx = np.arange(y.size)
        y[flagged] = np.interp(idx[flagged], idx[~flagged], y[~flagged])
    return y
