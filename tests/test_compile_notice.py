"""A first compile of the kernel is said, and waited for: the notice fires on a real numba compile of
a kernel-module function and on nothing else; the engine's start-up waits past its start timeout
once the engine says it is compiling, and still fails, loud and bounded, when it says nothing or
never finishes (a real child process on a real pipe)."""

import importlib.util
import multiprocessing as mp
import time
import uuid

import pytest

from hil_server.engine.process import EngineStartError, await_ready
from sim_core.kernel.compile_notice import on_kernel_compile
from sim_core.kernel.compose import MODULE_PREFIX

pytestmark = pytest.mark.realtime     # the start-up tests race a child's sleeps against timeouts


def _module(tmp_path, name):
    """A fresh module of two numba functions (not cached: each import compiles on first call)."""
    path = tmp_path / f"{name}.py"
    path.write_text("from numba import njit\n\n"
                    "@njit(cache=False)\ndef twice(x):\n    return 2.0 * x\n\n"
                    "@njit(cache=False)\ndef thrice(x):\n    return 3.0 * x\n")
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_notice_fires_once_on_a_kernel_compile_and_never_for_other_code(tmp_path):
    calls = []
    kernel_like = _module(tmp_path, f"{MODULE_PREFIX}{uuid.uuid4().hex[:12]}")
    other = _module(tmp_path, f"not_the_kernel_{uuid.uuid4().hex[:12]}")
    with on_kernel_compile(lambda: calls.append(1)):
        assert other.twice(1.0) == 2.0             # compiled, but not the kernel's
        assert calls == []
        assert kernel_like.twice(1.0) == 2.0       # compiled: said
        assert kernel_like.thrice(1.0) == 3.0      # compiled too: said once per block
        assert kernel_like.twice(2.0) == 4.0       # already compiled: no event
    assert calls == [1]
    late = _module(tmp_path, f"{MODULE_PREFIX}{uuid.uuid4().hex[:12]}")
    assert late.twice(1.0) == 2.0                   # outside the block: nobody listens
    assert calls == [1]


def _compiles_then_ready(conn, compile_s):
    conn.send((None, "compiling", {"notice": "compiling the simulation kernel (a test)"}))
    time.sleep(compile_s)
    conn.send((None, "ready", {"pid": 1}))
    time.sleep(30)


def _compiles_forever(conn):
    conn.send((None, "compiling", {"notice": "compiling the simulation kernel (a test)"}))
    time.sleep(60)


def _silent(conn):
    time.sleep(60)


def _fails(conn):
    conn.send((None, "error", "engine failed: no such effect\nTraceback (most recent call last): ..."))


def _start(target, *args):
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=target, args=(child, *args), daemon=True)
    proc.start()
    child.close()
    return parent, proc


def test_an_engine_that_is_compiling_gets_past_its_start_timeout():
    conn, proc = _start(_compiles_then_ready, 4.0)
    try:
        t0 = time.monotonic()
        info = await_ready(conn, proc, start_timeout=2.0, compile_timeout=60.0)
        assert info == {"pid": 1}
        assert time.monotonic() - t0 >= 3.5         # it did wait beyond the 2 s start timeout
    finally:
        proc.kill()


@pytest.mark.parametrize("target,said", [(_silent, "did not start within 1 s"),
                                         (_compiles_forever, "did not finish compiling the simulation kernel within 3 s")])
def test_an_engine_that_never_comes_up_fails_within_its_time_and_is_killed(target, said):
    conn, proc = _start(target)
    t0 = time.monotonic()
    with pytest.raises(EngineStartError, match=said):
        await_ready(conn, proc, start_timeout=1.0, compile_timeout=3.0)
    assert time.monotonic() - t0 < 30.0
    proc.join(10.0)
    assert not proc.is_alive()


def test_an_engine_that_fails_says_why():
    conn, proc = _start(_fails)
    with pytest.raises(EngineStartError, match="engine failed: no such effect"):
        await_ready(conn, proc, start_timeout=30.0)
    proc.join(10.0)
