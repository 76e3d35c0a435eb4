"""Shared memory between service and engine: the seqlock's barriers are real on ARM64, a reader never
takes a torn copy from a concurrent writer in another process, a copy that cannot be read
consistently is refused and counted (REST 503, /metrics), and hosts that cannot be supported are
refused with a reason."""

import multiprocessing as mp
import os
import re
import signal
import time

import httpx
import numpy as np
import pytest

from hil_server.engine import atomics as A
from hil_server.engine import shared as S

from web_helpers import InProcessServer

pytestmark = pytest.mark.realtime


def test_the_seqlock_compiles_to_acquire_release_barriers_on_arm64():
    """Cross-compile the compiled reader and writer for aarch64: the reader must load the sequence
    with acquire (ldar) and fence its data loads (dmb ishld) before re-checking; the writer must fence
    after making the sequence odd (dmb ish) and publish the even sequence with a release store (stlr).
    x86 needs none of these instructions, so only this check can fail when a barrier is dropped."""
    import llvmlite.binding as llvm
    from numba import njit

    llvm.initialize_all_targets()
    llvm.initialize_all_asmprinters()
    try:
        tm = llvm.Target.from_triple("aarch64-unknown-linux-gnu").create_target_machine(opt=2)
    except RuntimeError as exc:
        pytest.skip(f"this llvmlite has no AArch64 backend: {exc}")
    words, area, out = np.zeros(4, dtype=np.int64), np.ones(12), np.zeros(12)
    asm = {}
    for fn, args in ((A.read_consistent, (words, 1, area, out, 10)), (A.write_begin, (words, 1)),
                     (A.write_end, (words, 1))):
        f = njit(_nrt=False)(fn.py_func)   # a fresh, uncached compile whose LLVM IR can be inspected
        f(*args)
        mod = llvm.parse_assembly(f.inspect_llvm(f.signatures[0]))
        mod.triple = "aarch64-unknown-linux-gnu"
        asm[fn.py_func.__name__] = tm.emit_assembly(mod)
    assert re.search(r"\bldar\b", asm["read_consistent"]) and "dmb\tishld" in asm["read_consistent"]
    assert "dmb\tish" in asm["write_begin"]
    assert re.search(r"\bstlr\b", asm["write_end"])


def _writer(shm_name, layout, stop, counts):
    """Publishes every ~20 us (50 times the engine's 1 kHz) until told to stop."""
    import time

    block = S.SharedBlock(layout, name=shm_name)
    k = 0
    try:
        while not stop.is_set():
            k += 1
            A.write_begin(block.sync, S.W_STATE_SEQ)
            block.state[:] = float(k)          # every element carries the same value: a mix is visible
            A.write_end(block.sync, S.W_STATE_SEQ)
            t = time.perf_counter() + 20e-6
            while time.perf_counter() < t:
                pass
        counts.value = k
    finally:
        block.close()


def test_a_reader_never_gets_a_torn_copy_from_a_writer_in_another_process():
    layout = S.Layout(n_dof=40, n_act=40, n_sensed=0, rec_capacity=10)   # a big state area: long copies
    block = S.SharedBlock(layout)
    ctx = mp.get_context("spawn")
    stop, counts = ctx.Event(), ctx.Value("q", 0)
    p = ctx.Process(target=_writer, args=(block.name, layout, stop, counts))
    p.start()
    try:
        out = np.empty_like(block.state)
        while block.state[0] == 0.0:
            pass
        values, torn, failed = set(), 0, 0
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            try:
                snap = block.snapshot(out)
            except S.SnapshotError:
                failed += 1
                continue
            torn += int(not np.all(snap == snap[0]))
            values.add(float(snap[0]))
    finally:
        stop.set()
        p.join(10)
        block.close()
    assert torn == 0 and failed == 0
    assert counts.value > 1000 and len(values) > 50       # the writer really raced the reader
    assert block.read_failures["state"] == 0


def test_a_copy_that_cannot_be_read_consistently_is_refused_and_counted(tmp_path):
    """The engine stopped in the middle of an update (SIGSTOP while the sequence is odd): REST
    answers 503 instead of a torn state, /metrics counts the failed reads; both recover after."""
    srv = InProcessServer("hydrolek", tmp_path, viewer=False, stall_ms=60000.0)
    pid = srv.svc.supervisor.engine.pid
    try:
        with httpx.Client(base_url=srv.url, timeout=30) as c:
            assert c.get("/api/v1/state").status_code == 200
            os.kill(pid, signal.SIGSTOP)
            A.write_begin(srv.svc.block.sync, S.W_STATE_SEQ)        # the writer's half-done update
            try:
                r = c.get("/api/v1/state")
                assert r.status_code == 503 and "no consistent copy" in r.json()["detail"]
                line = [ln for ln in c.get("/metrics").text.splitlines()
                        if ln.startswith('hydrohil_shm_read_failures_total{area="state",reader="service"}')]
                assert line and int(line[0].split()[-1]) >= 1
            finally:
                A.write_end(srv.svc.block.sync, S.W_STATE_SEQ)
                os.kill(pid, signal.SIGCONT)
            assert c.get("/api/v1/state").status_code == 200
    finally:
        srv.close()


def test_hosts_that_cannot_be_supported_are_refused_with_a_reason():
    assert A.platform_problem("x86_64", 64) is None and A.platform_problem("aarch64", 64) is None
    msg = A.platform_problem("armv7l", 32)
    assert msg and "64-bit" in msg and "armv7l" in msg
    A.check_platform()   # this host: supported, helpers compile and behave
