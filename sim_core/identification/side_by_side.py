"""Independent simulations (and other independent jobs) run side by side in forked processes.

After the candidate search a diagnosis simulates a few models at the default integrator step (each
effect removed from the refitted model, the refitted model, the baseline, the columns of an
uncertainty Jacobian): a tenth of a second each, none needing another's result, while one core
would idle. Forked children inherit the compiled kernel, and what a batch names as ``hold`` (the
runner with its record, megabytes that would otherwise be pickled into every job); the model specs
travel by pickle. The outputs are those of running the same jobs here, in the same order.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor

from .simulation import Outputs, Runner

_HELD: list = [None]     # in a child: the ``hold`` of the batch that forked it


def held():
    """In a job run by :meth:`SideBySide.map`: the ``hold`` of its batch."""
    return _HELD[0]


def _simulate(job) -> Outputs:
    spec, n, resume = job
    return held().simulate(spec, n, owned=True, resume=resume)


def _simulate_carried(job) -> Outputs:
    runner, spec, n, resume = job
    return runner.simulate(spec, n, owned=True, resume=resume)


class SideBySide:
    """A pool of ``workers`` forked processes (0: the CPU count), started at the first batch of two
    or more; ``workers`` 1, or no fork on this platform: everything runs here."""

    def __init__(self, workers: int = 0):
        self.workers = workers or len(os.sched_getaffinity(0))
        self._pool: ProcessPoolExecutor | None = None
        self._hold = None       # what the children hold (kept alive here)

    def _parallel(self, count: int) -> bool:
        return self.workers > 1 and count > 1 and "fork" in multiprocessing.get_all_start_methods()

    def map(self, fn, items: list, hold=None) -> list:
        """``fn(item)`` for every item, in order (``fn`` a module-level function: it travels by pickle).
        ``hold``: an object ``fn`` reads as :func:`held`, which the children take from their fork
        (children forked for another one are replaced)."""
        if not self._parallel(len(items)):
            _HELD[0], before = hold, _HELD[0]
            try:
                return [fn(i) for i in items]
            finally:
                _HELD[0] = before
        if self._pool is not None and self._hold is not hold:
            self.close()
        if self._pool is None:
            self._hold = hold
            _HELD[0] = hold
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("fork"))
            # the children fork at the first submission: until then the parent's _HELD is theirs
            futures = [self._pool.submit(fn, i) for i in items]
            _HELD[0] = None
            return [f.result() for f in futures]
        return list(self._pool.map(fn, items))

    def simulate(self, runner: Runner, specs: list, n: int | None = None,
                 resume: list | None = None) -> list[Outputs]:
        """``runner.simulate(spec, n, resume=)`` for every spec, in order (``resume``: the outputs each
        may continue from, or None)."""
        resume = resume or [None] * len(specs)
        if self._parallel(len(specs)):
            runner.calls += len(specs)
            if self._pool is not None and self._hold is not runner:
                # children forked for another runner: this one travels with each job (cheaper than a new fork)
                return self.map(_simulate_carried, [(runner, s, n, r) for s, r in zip(specs, resume)], hold=self._hold)
        return self.map(_simulate, [(s, n, r) for s, r in zip(specs, resume)], hold=runner)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
            self._hold = None

    def __enter__(self) -> "SideBySide":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
