"""The real-time loop's timing rules with a scripted clock (the clock is EngineLoop's injected
dependency; plant, simulator and shared memory are the real ones): overrun counting, back-to-back
catch-up, resynchronisation after a stall over a second, the lateness ring, histogram and
percentiles."""

import multiprocessing as mp

import numpy as np
import pytest

from hil_server.engine import shared as S
from hil_server.engine.loop import RESYNC_S, EngineLoop
from hil_server.service.documents import lateness_summary
from sim_core.simulator import Simulator

DT = 1e-3


class ScriptedClock:
    """perf_counter stand-in: waiting for a deadline arrives at max(now, deadline) plus the scripted
    wake-up delay of that tick (what a busy OS does to a sleeping thread); the tick itself takes no
    time. After the last scripted tick the loop is told to stop."""

    def __init__(self, delays):
        self.t = 1000.0
        self.delays = list(delays)
        self.k = 0
        self.loop = None

    def now(self) -> float:
        return self.t

    def wait_until(self, deadline: float) -> None:
        self.t = max(self.t, deadline) + self.delays[self.k]
        self.k += 1
        if self.k == len(self.delays):
            self.loop.stop = True


@pytest.fixture
def make_loop(plants):
    made = []

    def make(delays):
        plant = plants("hydrolek")
        ctx = plant.create_context()
        spec = plant.spec
        layout = S.Layout(spec.tree.n, len(spec.joints), len(spec.sensed_joints), 1000)
        block = S.SharedBlock(layout)
        a, b = mp.Pipe()
        clock = ScriptedClock(delays)
        loop = EngineLoop(ctx, Simulator(ctx), block, b, dt=DT, mode="realtime", watchdog_s=0.1,
                          realtime_priority=False, clock=clock)
        clock.loop = loop
        made.append((block, a, b))
        return loop

    yield make
    for block, a, b in made:
        a.close()
        b.close()
        block.close()


def run(loop):
    t0 = loop.ctx.time
    loop.run()
    st = loop.block.stats
    n = int(st[S.T_RING_N])
    ring = loop.block.ring[:min(n, S.LATENESS_RING)].copy()
    return {"ticks": int(st[S.T_TICKS]), "overruns": int(st[S.T_OVERRUNS]), "resyncs": int(st[S.T_RESYNCS]),
            "sim_s": loop.ctx.time - t0, "ring": ring, "written": n, "buckets": loop.block.buckets.copy()}


def test_a_short_stall_is_caught_up_back_to_back_and_late_ticks_are_overruns(make_loop):
    stall = 5.5e-3
    r = run(make_loop([0.0] * 100 + [stall] + [0.0] * 200))
    assert r["ticks"] == 301 and r["resyncs"] == 0
    assert r["sim_s"] == pytest.approx(301 * DT, abs=1e-9)       # no tick skipped: plant time kept pace
    # the stalled tick starts 5.5 ms late, the next ones run at once, each 1 ms less late
    np.testing.assert_allclose(r["ring"][100:106], [5.5e-3, 4.5e-3, 3.5e-3, 2.5e-3, 1.5e-3, 0.5e-3], atol=1e-12)
    assert np.all(r["ring"][:100] == 0.0) and np.all(r["ring"][106:] == 0.0)
    assert r["overruns"] == 5                                      # late by a whole period or more


def test_a_stall_over_a_second_resynchronises_instead_of_running_a_second_flat_out(make_loop):
    r = run(make_loop([0.0] * 10 + [RESYNC_S + 0.5] + [0.0] * 20))
    assert r["ticks"] == 31 and r["resyncs"] == 1 and r["overruns"] == 1
    assert r["sim_s"] == pytest.approx(31 * DT, abs=1e-9)          # the missed 1.5 s are not integrated
    assert np.all(r["ring"][11:] == 0.0)                           # back on schedule right after


def test_a_stall_just_under_a_second_is_caught_up_tick_by_tick(make_loop):
    r = run(make_loop([0.0] * 5 + [0.9055] + [0.0] * 1000))
    assert r["resyncs"] == 0
    assert r["ticks"] == 1006 and r["sim_s"] == pytest.approx(1006 * DT, abs=1e-9)
    assert r["overruns"] == 905                                    # 905.5, 904.5, ... 1.5 ms late
    assert r["ring"][5] == pytest.approx(0.9055) and r["ring"][910] == pytest.approx(0.5e-3)


def test_lateness_ring_histogram_and_percentiles_follow_the_ticks(make_loop):
    rng = np.random.default_rng(7)
    delays = rng.uniform(0.0, 0.9e-3, 12000)            # each tick late by less than a period: no catch-up
    r = run(make_loop(delays))
    assert r["ticks"] == 12000 and r["overruns"] == 0 and r["written"] == 12000
    # the ring keeps the last LATENESS_RING ticks, oldest overwritten first
    window = delays[-S.LATENESS_RING:]
    np.testing.assert_allclose(np.sort(r["ring"]), np.sort(window), atol=1e-12)
    summary = lateness_summary(r["ring"], r["written"])
    assert summary["window_ticks"] == S.LATENESS_RING
    for key, q in (("p50", 50), ("p99", 99), ("p999", 99.9)):
        assert summary[key] == pytest.approx(np.percentile(window, q) * 1e6, rel=1e-9)
    assert summary["max"] == pytest.approx(window.max() * 1e6)
    # histogram: every tick in the first bucket whose bound it does not exceed
    edges = np.array(S.LATENESS_BUCKETS_US) * 1e-6
    expected = [np.count_nonzero(delays <= edges[0])]
    expected += [np.count_nonzero((delays > lo) & (delays <= hi)) for lo, hi in zip(edges[:-1], edges[1:])]
    expected.append(np.count_nonzero(delays > edges[-1]))
    np.testing.assert_array_equal(r["buckets"], expected)
