"""Independent simulations (and other independent jobs) run side by side in forked processes.

After the candidate search a diagnosis simulates a few models at the default integrator step (each
effect removed from the refitted model, the refitted model, the baseline, the columns of an
uncertainty Jacobian): a tenth of a second each, none needing another's result, while one core
would idle. Forked children inherit the compiled kernel; the runner and the model specs travel
by pickle. The outputs are those of running the same simulations here, in the same order.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor

from .simulation import Outputs, Runner


def _simulate(job) -> Outputs:
    runner, spec, n = job
    return runner.simulate(spec, n, owned=True)


class SideBySide:
    """A pool of ``workers`` forked processes (0: the CPU count), started at the first batch of two
    or more; ``workers`` 1, or no fork on this platform: everything runs here."""

    def __init__(self, workers: int = 0):
        self.workers = workers or len(os.sched_getaffinity(0))
        self._pool: ProcessPoolExecutor | None = None

    def _parallel(self, count: int) -> bool:
        return self.workers > 1 and count > 1 and "fork" in multiprocessing.get_all_start_methods()

    def map(self, fn, items: list) -> list:
        """``fn(item)`` for every item, in order (``fn`` a module-level function: it travels by pickle)."""
        if not self._parallel(len(items)):
            return [fn(i) for i in items]
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("fork"))
        return list(self._pool.map(fn, items))

    def simulate(self, runner: Runner, specs: list, n: int | None = None) -> list[Outputs]:
        """``runner.simulate(spec, n)`` for every spec, in order."""
        if not self._parallel(len(specs)):
            return [runner.simulate(s, n) for s in specs]
        runner.calls += len(specs)
        return self.map(_simulate, [(runner, s, n) for s in specs])

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def __enter__(self) -> "SideBySide":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
