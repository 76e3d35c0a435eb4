"""The service's configuration and the error every part raises for a refused request."""

from __future__ import annotations

from dataclasses import dataclass, field


class ServiceError(ValueError):
    """A request the service refuses; the API maps it to ``status`` (4xx/503) with this message."""

    def __init__(self, msg: str, status: int = 422):
        super().__init__(msg)
        self.status = status


@dataclass
class ServiceConfig:
    robot: str = "mars_nd"
    host: str = "127.0.0.1"
    port: int = 8000
    can: str | None = "socketcand:29536"
    viewer_port: int | None = 8080
    viewer_host: str = "127.0.0.1"
    rate_hz: float = 1000.0
    mode: str = "realtime"
    params: str | None = None
    token: str | None = None
    insecure: bool = False            # a non-loopback bind without a token, accepted with warnings
    watchdog_ms: float = 100.0
    feedback_rate_hz: float = 100.0
    recordings_dir: str = "recordings"
    seed: int = 0
    node_id: int = 0x10
    realtime_priority: bool = True
    recording_ring_s: float = 60.0
    engine_cpu: int | None = None
    engine_restart: str = "auto"      # auto | never
    max_restarts_per_min: int = 5
    stall_ms: float = 100.0           # no loop progress for this long = a stalled engine
    alive_counter_limit: int = 3      # ValveCommand counter errors in a row tolerated per joint (0: no check)
    warnings: list[str] = field(default_factory=list)   # security warnings shown in the log, /health, viewer
    extra: dict = field(default_factory=dict)
