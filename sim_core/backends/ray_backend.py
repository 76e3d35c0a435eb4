"""The Ray backend: each task a Ray task of one CPU, on a new local Ray instance or a running cluster.

``shared`` goes to the object store once per ``map``; every worker must run the same hydrohil (the
driver's code fingerprint travels with each task and a worker with other code refuses it, so a
cluster with a stale install fails loudly instead of diagnosing with other physics). Each Ray worker
process loads the compiled kernel on its first task (from the kernel cache on disk, or compiles it
on a node that has none): that first task is slower, and ``Outcome.task['first']`` says which it was.
"""

from __future__ import annotations

import socket
import time

import ray
from ray.exceptions import RayError, RayTaskError

from . import BackendError, Outcome, run_task, top_up
from .fingerprint import code_fingerprint


CONNECT_TIMEOUT_S = 10.0    # Ray itself retries an unreachable address for many minutes


def _check_reachable(address: str) -> str:
    """The cluster's host:port, checked to accept a connection (Ray would wait for it, not fail)."""
    target = address.removeprefix("ray://")
    if target == "auto":
        try:
            from ray._private.services import canonicalize_bootstrap_address
        except ImportError:        # that helper moved: let ray.init resolve 'auto' itself
            return address
        try:
            target = canonicalize_bootstrap_address("auto")
        except ConnectionError as exc:
            raise BackendError(f"--address auto: no running Ray cluster on this machine ({exc}); start one with "
                               f"'ray start --head', or leave --address out for a local instance") from None
    host, sep, port = target.rpartition(":")
    if not sep or not port.isdigit():
        raise BackendError(f"--address {address!r}: expected HOST:PORT (the address 'ray start --head' prints), "
                           f"ray://HOST:PORT or auto")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise BackendError(f"--address {address}: no Ray cluster answers at {host}:{port} ({exc.strerror or exc}); "
                           f"start one with 'ray start --head', or leave --address out for a local instance") from None
    return address


def _remote_task(fingerprint: str, fn, shared, item):
    mine = code_fingerprint()
    if mine != fingerprint:
        raise RuntimeError(f"this Ray worker runs other hydrohil code ({mine}) than the driver ({fingerprint}): "
                           f"install the same hydrohil on every node of the cluster")
    return run_task(fn, shared, item)


class RayBackend:
    name = "ray"

    def __init__(self, address: str | None = None, workers: int = 0):
        self.owned = not ray.is_initialized()
        if self.owned:
            kw = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
            try:
                if address in (None, "", "local"):
                    ray.init(address="local", num_cpus=workers or None, **kw)
                else:
                    ray.init(address=_check_reachable(address), **kw)
            except (ConnectionError, RuntimeError, ValueError) as exc:
                raise BackendError(f"--address {address}: no Ray cluster to connect to ({exc}); start one with "
                                   f"'ray start --head', or leave --address out for a local instance") from None
        self.cpus = int(ray.cluster_resources().get("CPU", 1))
        self.slots = workers or self.cpus
        self.address = ray.get_runtime_context().gcs_address
        self._fingerprint = code_fingerprint()
        self._task = ray.remote(num_cpus=1, max_retries=1)(_remote_task)

    def describe(self) -> str:
        return f"ray at {self.address} ({self.cpus} CPUs, {self.slots} task{'s' if self.slots > 1 else ''} at a time)"

    def map(self, fn, shared, items):
        ref = ray.put(shared)
        it = iter(items)
        pending: dict = {}
        more = True
        try:
            while True:
                if more:
                    more = top_up(pending, it, self.slots, lambda item: self._task.remote(self._fingerprint, fn, ref, item))
                if not pending:
                    return
                ready, _ = ray.wait(list(pending), num_returns=1)
                for r in ready:
                    item, t0 = pending.pop(r)
                    try:
                        value, task = ray.get(r)
                    except RayTaskError as exc:       # the task raised: its own exception, as raised there
                        cause = exc.cause if isinstance(getattr(exc, "cause", None), BaseException) else exc
                        yield Outcome(item, error=cause, seconds=time.perf_counter() - t0)
                    except RayError as exc:           # the worker died or the task was lost
                        yield Outcome(item, error=exc, seconds=time.perf_counter() - t0)
                    else:
                        yield Outcome(item, value, seconds=time.perf_counter() - t0, task=task)
        finally:
            for r in pending:
                ray.cancel(r, force=True)

    def close(self) -> None:
        if self.owned and ray.is_initialized():
            ray.shutdown()

