"""Background imports: a fork of the process waits for them, errors stay quiet, the report's plotting
library can be preloaded and the report drawn afterwards."""

import os
import threading
import time

import pytest

from sim_core import background_import

pytestmark = pytest.mark.realtime


def _slow(done: threading.Event, seconds: float = 0.4):
    def load():
        time.sleep(seconds)
        done.set()
    return load


def test_a_fork_waits_for_a_background_import_under_way():
    done = threading.Event()
    background_import.start(_slow(done))
    pid = os.fork()
    if pid == 0:                 # the child: nothing to do
        os._exit(0)
    finished_before_fork_returned = done.is_set()
    os.waitpid(pid, 0)
    assert finished_before_fork_returned


def test_wait_returns_once_every_import_has_finished():
    done = [threading.Event(), threading.Event()]
    for ev, s in zip(done, (0.2, 0.4)):
        background_import.start(_slow(ev, s))
    background_import.wait()
    assert all(ev.is_set() for ev in done)
    t0 = time.perf_counter()
    background_import.wait()          # nothing left: returns at once
    assert time.perf_counter() - t0 < 0.1


def test_a_second_waiter_also_waits_for_the_import_another_thread_waits_for():
    done = threading.Event()
    background_import.start(_slow(done))
    first = threading.Thread(target=background_import.wait)
    first.start()
    time.sleep(0.1)                   # the first waiter is joining the import
    background_import.wait()
    assert done.is_set()
    first.join()


def test_a_failing_import_is_not_raised_in_the_background(monkeypatch):
    raised = []
    monkeypatch.setattr(threading, "excepthook", lambda args: raised.append(args.exc_value))

    def broken():
        import sim_core.no_such_module  # noqa: F401
    background_import.start(broken)
    background_import.wait()
    assert raised == []


def test_the_report_preloads_its_plotting_library():
    from sim_core.identification import report

    report.preload()
    background_import.wait()
    import sys
    assert "matplotlib.pyplot" in sys.modules
    plt = report._pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    assert report._png(fig)            # a figure drawn with the preloaded library
