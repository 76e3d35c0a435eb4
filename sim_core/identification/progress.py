"""The progress bar of a candidate round: fits done of the round's total, and the best candidate so
far with its validation gain (NRMSE points), so a user watching a long diagnosis sees where it leans."""

from __future__ import annotations

import math
import sys


class RoundProgress:
    """A tqdm bar on stderr (nothing drawn when ``enabled`` is false); :meth:`done` per finished fit."""

    def __init__(self, total: int, desc: str, enabled: bool, *, file=None, mininterval: float = 0.1):
        from tqdm import tqdm

        self._bar = tqdm(total=total, desc=desc, unit="fit", disable=not enabled, file=file or sys.stderr,
                         leave=False, mininterval=mininterval)
        self.best = None            # the Evaluation with the highest finite gain so far

    def done(self, ev) -> None:
        """One candidate fitted: count it; show it when it beats the best so far (a failed fit's
        non-finite gain never does)."""
        if math.isfinite(ev.gain) and (self.best is None or ev.gain > self.best.gain):
            self.best = ev
            self._bar.set_postfix_str(f"best {ev.candidate.label} {ev.gain:+.1f}", refresh=False)
        self._bar.update(1)

    def close(self) -> None:
        self._bar.close()
