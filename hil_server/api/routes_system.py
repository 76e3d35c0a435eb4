"""Health and Prometheus metrics."""

from fastapi import APIRouter, Depends
from fastapi.responses import PlainTextResponse

from ..engine import shared as S
from .deps import get_service
from .schemas import HealthResponse, model_json

router = APIRouter(tags=["system"])


@router.get("/api/v1/health", response_model=HealthResponse)
async def health(svc=Depends(get_service)):
    """Liveness, mode, and whether the loop got real-time priority (and why not)."""
    return model_json(HealthResponse, svc.health())


@router.get("/metrics", response_class=PlainTextResponse)
async def metrics(svc=Depends(get_service)):
    """Prometheus text format: loop lateness histogram, overruns, HTTP requests, CAN frames."""
    st = svc.block.stats
    lines = [
        "# HELP hydrohil_loop_ticks_total Plant ticks executed.",
        "# TYPE hydrohil_loop_ticks_total counter",
        f"hydrohil_loop_ticks_total {int(st[S.T_TICKS])}",
        "# HELP hydrohil_loop_overruns_total Ticks started a full period or more after their deadline.",
        "# TYPE hydrohil_loop_overruns_total counter",
        f"hydrohil_loop_overruns_total {int(st[S.T_OVERRUNS])}",
        "# HELP hydrohil_loop_resyncs_total Stalls longer than a second after which the clock was resynchronised.",
        "# TYPE hydrohil_loop_resyncs_total counter",
        f"hydrohil_loop_resyncs_total {int(st[S.T_RESYNCS])}",
        "# HELP hydrohil_watchdog_trips_total Valves put to neutral by the command watchdog.",
        "# TYPE hydrohil_watchdog_trips_total counter",
        f"hydrohil_watchdog_trips_total {int(st[S.T_WD_TRIPS])}",
        "# HELP hydrohil_loop_lateness_seconds Tick start minus deadline (realtime mode).",
        "# TYPE hydrohil_loop_lateness_seconds histogram",
    ]
    cum = 0
    for i, b in enumerate(S.LATENESS_BUCKETS_US):
        cum += int(svc.block.buckets[i])
        lines.append(f'hydrohil_loop_lateness_seconds_bucket{{le="{b * 1e-6:g}"}} {cum}')
    cum += int(svc.block.buckets[len(S.LATENESS_BUCKETS_US)])
    lines.append(f'hydrohil_loop_lateness_seconds_bucket{{le="+Inf"}} {cum}')
    n = int(st[-1])
    ring = svc.block.ring[: min(n, svc.block.ring.shape[0])]
    lines.append(f"hydrohil_loop_lateness_seconds_count {cum}")
    lines.append(f"hydrohil_loop_lateness_seconds_sum {float(ring.sum()) * (cum / max(1, ring.size)):.6f}")
    lines += ["# HELP hydrohil_http_requests_total HTTP requests by method, route and status.",
              "# TYPE hydrohil_http_requests_total counter"]
    for (method, route, code), count in sorted(svc.metrics.http.items()):
        lines.append(f'hydrohil_http_requests_total{{method="{method}",route="{route}",status="{code}"}} {count}')
    if svc.bridge is not None:
        lines += ["# HELP hydrohil_can_frames_total CAN frames by direction and kind.",
                  "# TYPE hydrohil_can_frames_total counter"]
        for (direction, kind), count in sorted(svc.bridge.counters.items()):
            lines.append(f'hydrohil_can_frames_total{{direction="{direction}",kind="{kind}"}} {count}')
    return "\n".join(lines) + "\n"
