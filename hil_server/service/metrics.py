"""Counters for the Prometheus endpoint and the text it serves."""

from __future__ import annotations

import threading

from ..engine import shared as S


class Metrics:
    """Service-side counters (HTTP requests, dropped engine replies); the rest is read from the parts."""

    def __init__(self):
        self.http: dict[tuple[str, str, int], int] = {}
        self._lock = threading.Lock()

    def count_http(self, method: str, route: str, status: int) -> None:
        key = (method, route, status)
        with self._lock:
            self.http[key] = self.http.get(key, 0) + 1


def _metric(lines: list, name: str, kind: str, help_: str, samples) -> None:
    lines += [f"# HELP {name} {help_}", f"# TYPE {name} {kind}"]
    for labels, value in samples:
        lab = "{" + ",".join(f'{k}="{v}"' for k, v in labels.items()) + "}" if labels else ""
        lines.append(f"{name}{lab} {value}")


def render(svc) -> str:
    """Prometheus text format: loop, engine supervision, plant faults, shared memory, HTTP, CAN."""
    block = svc.block
    st = block.stats
    sup = svc.supervisor
    lines: list[str] = []
    _metric(lines, "hydrohil_loop_ticks_total", "counter", "Plant ticks executed.", [({}, int(st[S.T_TICKS]))])
    _metric(lines, "hydrohil_loop_overruns_total", "counter", "Ticks started a full period or more after their deadline.",
            [({}, int(st[S.T_OVERRUNS]))])
    _metric(lines, "hydrohil_loop_resyncs_total", "counter",
            "Stalls longer than a second after which the clock was resynchronised.", [({}, int(st[S.T_RESYNCS]))])
    _metric(lines, "hydrohil_watchdog_trips_total", "counter", "Valves put to neutral by the command watchdog.",
            [({}, int(st[S.T_WD_TRIPS]))])
    lines += ["# HELP hydrohil_loop_lateness_seconds Tick start minus deadline (realtime mode).",
              "# TYPE hydrohil_loop_lateness_seconds histogram"]
    cum = 0
    for i, b in enumerate(S.LATENESS_BUCKETS_US):
        cum += int(block.buckets[i])
        lines.append(f'hydrohil_loop_lateness_seconds_bucket{{le="{b * 1e-6:g}"}} {cum}')
    cum += int(block.buckets[len(S.LATENESS_BUCKETS_US)])
    lines.append(f'hydrohil_loop_lateness_seconds_bucket{{le="+Inf"}} {cum}')
    n = int(st[S.T_RING_N])
    ring = block.ring[: min(n, block.ring.shape[0])]
    lines.append(f"hydrohil_loop_lateness_seconds_count {cum}")
    lines.append(f"hydrohil_loop_lateness_seconds_sum {float(ring.sum()) * (cum / max(1, ring.size)):.6f}")
    _metric(lines, "hydrohil_engine_up", "gauge", "1 while the engine process runs and its loop makes progress.",
            [({}, int(sup.running))])
    _metric(lines, "hydrohil_engine_failures_total", "counter", "Engine deaths and stalls, by kind.",
            [({"kind": k}, sup.failures.get(k, 0)) for k in ("died", "stalled")])
    _metric(lines, "hydrohil_engine_restarts_total", "counter", "Engine restarts (--engine-restart auto).",
            [({}, sup.restarts)])
    eng = sup.engine
    _metric(lines, "hydrohil_engine_dropped_replies_total", "counter",
            "Engine replies that answered no pending request (late after a timeout, or unsolicited).",
            [({}, eng.dropped_replies if eng is not None else 0)])
    _metric(lines, "hydrohil_plant_rollbacks_total", "counter", "Plant steps rejected as non-finite and rolled back.",
            [({}, int(st[S.T_ROLLBACKS]))])
    _metric(lines, "hydrohil_plant_diverged_total", "counter", "Times the diverged fault was latched.",
            [({}, int(st[S.T_DIVERGED]))])
    _metric(lines, "hydrohil_plant_diverged", "gauge", "1 while the diverged fault holds the valves neutral.",
            [({}, int(svc.faults.diverged is not None))])
    _metric(lines, "hydrohil_shm_read_failures_total", "counter",
            "Seqlocked shared-memory reads that found no consistent copy (never used), by area and reader.",
            [({"area": "state", "reader": "service"}, block.read_failures["state"]),
             ({"area": "commands", "reader": "service"}, block.read_failures["commands"]),
             ({"area": "commands", "reader": "engine"}, int(st[S.T_CMD_READ_FAILS]))])
    _metric(lines, "hydrohil_insecure", "gauge", "1 when serving beyond loopback without a token (--insecure).",
            [({}, int(bool(svc.cfg.insecure)))])
    _metric(lines, "hydrohil_http_requests_total", "counter", "HTTP requests by method, route and status.",
            [({"method": m, "route": r, "status": c}, v) for (m, r, c), v in sorted(svc.metrics.http.items())])
    if svc.bridge is not None:
        _metric(lines, "hydrohil_can_frames_total", "counter", "CAN frames by direction and kind.",
                [({"direction": d, "kind": k}, v) for (d, k), v in sorted(svc.bridge.counters.items())])
    return "\n".join(lines) + "\n"
