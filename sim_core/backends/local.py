"""The local backend: a pool of processes forked from this one (spawned where fork is missing).

Forked workers inherit ``shared`` without pickling it and whatever this process has loaded. A worker
that dies (a crash in compiled code) breaks the pool: the tasks in flight then fail with that error,
and a fresh pool takes the remaining ones.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from . import Outcome, run_task, top_up

_SHARED: list = []


def _install(shared) -> None:
    _SHARED[:] = [shared]


def _call(fn, item):
    return run_task(fn, _SHARED[0], item)


class LocalBackend:
    name = "local"

    def __init__(self, workers: int = 0):
        self.slots = workers or os.cpu_count() or 1

    def describe(self) -> str:
        return f"local ({self.slots} process{'es' if self.slots > 1 else ''})"

    def map(self, fn, shared, items):
        if self.slots <= 1:
            yield from self._serial(fn, shared, items)
            return
        methods = multiprocessing.get_all_start_methods()
        ctx = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
        it = iter(items)
        more = True
        while True:
            pool = ProcessPoolExecutor(max_workers=self.slots, mp_context=ctx, initializer=_install, initargs=(shared,))
            pending: dict = {}
            broken = False
            try:
                while True:
                    if more:
                        more = top_up(pending, it, self.slots, lambda item: pool.submit(_call, fn, item))
                    if not pending:
                        break
                    done, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for f in done:
                        item, t0 = pending.pop(f)
                        try:
                            value, task = f.result()
                        except BrokenProcessPool as exc:
                            broken = True
                            yield Outcome(item, error=exc, seconds=time.perf_counter() - t0)
                        except Exception as exc:   # the task's own error: its outcome, the others go on
                            yield Outcome(item, error=exc, seconds=time.perf_counter() - t0)
                        else:
                            yield Outcome(item, value, seconds=time.perf_counter() - t0, task=task)
                    if broken:
                        for f, (item, t0) in pending.items():
                            yield Outcome(item, error=BrokenProcessPool("a worker process died while this task ran"),
                                          seconds=time.perf_counter() - t0)
                        pending.clear()
                        break
            finally:
                pool.shutdown(wait=True, cancel_futures=True)
            if not broken or not more:
                return

    @staticmethod
    def _serial(fn, shared, items):
        for item in items:
            t0 = time.perf_counter()
            try:
                value, task = run_task(fn, shared, item)
            except Exception as exc:
                yield Outcome(item, error=exc, seconds=time.perf_counter() - t0)
            else:
                yield Outcome(item, value, seconds=time.perf_counter() - t0, task=task)

    def close(self) -> None:
        pass

