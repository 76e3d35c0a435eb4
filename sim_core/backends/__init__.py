"""Where independent tasks run: processes forked from this one (``local``) or Ray tasks (``ray``).

A backend maps a module-level function over items, ``fn(shared, item)`` for each, with ``shared``
sent to the workers once; outcomes come back as they complete (not in order), with at most
``slots`` tasks in flight, so the items can be produced lazily (a fleet's records are read as they
are submitted). A task that raises, or whose worker dies, gives an outcome with ``error`` set; the
other tasks go on.

    local.py        a pool of processes forked from this one (the default)
    ray_backend.py  Ray tasks on a local instance or a running cluster (``pip install hydrohil[ray]``)

The diagnosis maps its candidate fits over a backend (``diagnose --backend ray``), the fleet its
records (``diagnose-fleet``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Iterator, Protocol

BACKENDS = ("local", "ray")
RAY_MISSING = ("--backend ray needs Ray, an optional extra: pip install 'hydrohil[ray]' "
               "(or pip install 'ray[default]>=2.9' into the same environment)")


class BackendError(Exception):
    """The backend cannot be used (Ray missing, no cluster at the address)."""


@dataclass
class Outcome:
    """One task's result (``value``) or what went wrong (``error``), with where the time went."""

    item: Any
    value: Any = None
    error: BaseException | None = None
    seconds: float = 0.0                 # submit to result, seen by the caller (s)
    task: dict = field(default_factory=dict)   # seen by the worker: seconds, first (its first task), worker


class Backend(Protocol):
    name: str
    slots: int                           # tasks in flight at most

    def map(self, fn: Callable[[Any, Any], Any], shared: Any, items: Iterable) -> Iterator[Outcome]: ...

    def describe(self) -> str: ...

    def close(self) -> None: ...


def open_backend(name: str, *, address: str | None = None, workers: int = 0) -> Backend:
    """``local`` (``workers`` processes, default the CPU count) or ``ray`` (at ``address``: a running
    cluster, 'auto' for the one on this machine; default a new local instance of ``workers`` CPUs)."""
    if workers < 0:
        raise BackendError(f"--workers {workers}: must be 0 (all CPUs) or more")
    if name == "local":
        if address:
            raise BackendError("--address is for --backend ray")
        from .local import LocalBackend

        return LocalBackend(workers)
    if name == "ray":
        try:
            from .ray_backend import RayBackend
        except ImportError as exc:
            if (exc.name or "").split(".")[0] == "ray":
                raise BackendError(RAY_MISSING) from None
            raise
        return RayBackend(address, workers)
    raise BackendError(f"--backend {name!r}: expected one of {', '.join(BACKENDS)}")


_END = object()


def top_up(pending: dict, items: Iterator, slots: int, submit: Callable[[Any], Any]) -> bool:
    """Submit items until ``slots`` tasks are in flight (``pending``: handle -> (item, submit time));
    False once ``items`` is exhausted."""
    import time

    while len(pending) < slots:
        item = next(items, _END)
        if item is _END:
            return False
        pending[submit(item)] = (item, time.perf_counter())
    return True


_TASKS_RUN = {"pid": None, "n": 0}     # per process: a forked worker starts its own count


def run_task(fn, shared, item) -> tuple[Any, dict]:
    """Worker side of every backend: ``fn(shared, item)`` with the worker's own timing. ``first``
    marks the first task of a worker process (it loads the compiled kernel: the per-worker cost)."""
    import os
    import socket
    import time

    if _TASKS_RUN["pid"] != os.getpid():
        _TASKS_RUN.update(pid=os.getpid(), n=0)
    first = _TASKS_RUN["n"] == 0
    _TASKS_RUN["n"] += 1
    t0 = time.perf_counter()
    value = fn(shared, item)
    return value, {"seconds": time.perf_counter() - t0, "first": first, "worker": f"{socket.gethostname()}:{os.getpid()}"}
