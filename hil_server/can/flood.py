"""Flood limiting per CAN id: a token bucket for every arbitration id.

A node babbling on one id (a stuck transmitter, a fuzzer, a wrong bit rate elsewhere) only uses up
that id's budget; every other id keeps its own, so valid ValveCommand frames are never starved by a
flood on an unknown id. Ids beyond ``max_ids`` distinct ones (an id sweep) share one overflow bucket.
"""

from __future__ import annotations

OVERFLOW = -1


class IdRateLimiter:
    def __init__(self, rate: float, burst: float | None = None, max_ids: int = 4096):
        self.rate = float(rate)                      # frames/s admitted per id
        self.burst = float(burst if burst is not None else max(1.0, rate / 10.0))
        self.max_ids = max_ids
        self._buckets: dict[int, list[float]] = {}  # key -> [tokens, last time, last report time]

    @staticmethod
    def key(arbitration_id: int, extended: bool) -> int:
        return arbitration_id | (1 << 29 if extended else 0)

    def admit(self, key: int, now: float) -> bool:
        b = self._buckets.get(key)
        if b is None:
            if len(self._buckets) >= self.max_ids:
                key = OVERFLOW
                b = self._buckets.get(OVERFLOW)
            if b is None:
                b = self._buckets[key] = [self.burst, now, -1e9]
        tokens = min(self.burst, b[0] + (now - b[1]) * self.rate)
        b[1] = now
        if tokens < 1.0:
            b[0] = tokens
            return False
        b[0] = tokens - 1.0
        return True

    def report_due(self, key: int, now: float, every_s: float = 1.0) -> bool:
        """True at most once per ``every_s`` per id: when to say (EMCY) that an id is being dropped."""
        b = self._buckets.get(key) or self._buckets.get(OVERFLOW)
        if b is None or now - b[2] < every_s:
            return False
        b[2] = now
        return True
