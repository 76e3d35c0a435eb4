"""Slow imports done on a spare core while this process works on the other.

The diagnosis spends its first second on one core (the numerics check and the baseline calibration:
compiled simulations that release the GIL) before it forks its workers; the report's plotting
library (matplotlib, a quarter to a third of a second to import) fits in that time in a thread.

A process must not fork while another of its threads is importing: the child would inherit a
module's import lock held by a thread it does not have, and hang at its first import of that
module. Every fork of this process therefore waits for the imports under way to finish
(``os.register_at_fork``), as does :func:`wait`.
"""

from __future__ import annotations

import os
import threading
from typing import Callable

_running: list[threading.Thread] = []
_guard = threading.Lock()


def start(load: Callable[[], object]) -> None:
    """Run ``load`` (an import) in a background thread. An error is not raised here: the caller's
    own import later raises it where it is needed."""

    def run():
        try:
            load()
        except Exception:       # noqa: BLE001 - the foreground import reports it
            pass

    # not a daemon: the interpreter's exit waits for it, instead of finalising beside a half-done
    # import whose module locks an exit handler might need
    t = threading.Thread(target=run, name="background-import", daemon=False)
    with _guard:
        _running[:] = [r for r in _running if r.is_alive()]
        t.start()
        _running.append(t)


def wait() -> None:
    """Return once every import started here has finished (also when another thread waits too: a
    thread stays listed until it is done, so no waiter returns while one still runs)."""
    with _guard:
        running = list(_running)
    for t in running:
        t.join()


os.register_at_fork(before=wait)
