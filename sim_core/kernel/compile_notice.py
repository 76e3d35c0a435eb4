"""Tell a caller when the simulation kernel is being compiled rather than loaded from the cache.

numba compiles the composed kernel on its first use on a machine (again after an upgrade, and for a
robot whose arguments have other types, e.g. the first one with a prismatic joint): one to three
minutes on a small machine, with nothing to show for it. A caller that would otherwise look hung,
or time out (a CLI command, the HIL engine's start-up), registers a callback here and says so.
"""

from __future__ import annotations

from contextlib import contextmanager

from numba.core import event

from .compose import MODULE_PREFIX, cache_dir


def _is_kernel(ev) -> bool:
    data = ev.data if isinstance(ev.data, dict) else {}
    func = getattr(data.get("dispatcher"), "py_func", None)
    return (getattr(func, "__module__", None) or "").startswith(MODULE_PREFIX)


class _KernelCompileListener(event.Listener):
    """Calls back once, at the start of the first compilation of a kernel function (a load from
    numba's cache is not an event)."""

    def __init__(self, callback):
        self.callback = callback
        self.fired = False

    def on_start(self, ev) -> None:
        if not self.fired and _is_kernel(ev):
            self.fired = True
            self.callback()

    def on_end(self, ev) -> None:
        pass


@contextmanager
def on_kernel_compile(callback):
    """Within the block, call ``callback()`` (no arguments) once, when numba starts compiling a
    function of the generated kernel module; never when the kernel comes from the cache."""
    with event.install_listener("numba:compile", _KernelCompileListener(callback)):
        yield


def notice() -> str:
    """The line a caller shows while the kernel compiles (the CLI on stderr, the service in its log)."""
    return (f"compiling the simulation kernel (its first use on this machine: a minute or more; cached in "
            f"{cache_dir()} for later runs)")
