"""Request and response bodies. Unknown fields, NaN and infinities are refused (422)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

Finite = Field(allow_inf_nan=False)


def model_json(model: type[BaseModel], data: dict):
    """Validate ``data`` against ``model`` and return it as a JSON response. Fast path for hot
    endpoints: pydantic-core validates and dumps the state document in ~45 us, where FastAPI's
    generic encoder takes ~800 us."""
    from fastapi.responses import Response

    return Response(content=model.model_validate(data).model_dump_json(), media_type="application/json")


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class CommandRequest(Strict):
    voltages: dict[str, float] = Field(description="command voltage per joint (V)", min_length=1)
    source: Literal["rest", "viewer"] = Field("rest", description="who commands (shown in the state); CAN commands come over CAN")


class CommandResponse(BaseModel):
    applied: dict[str, float]
    estop: bool


class EstopRequest(Strict):
    engaged: bool = Field(description="true: all valves neutral until released")


class ChannelWrite(Strict):
    value: float = Field(description="analog output voltage (V), 0 to the amplifier's input range")


class ModeRequest(Strict):
    mode: Literal["realtime", "paused", "lockstep", "fast"]


class StepRequest(Strict):
    ticks: int = Field(1, ge=1, le=100_000, description="ticks to advance (lockstep mode)")


class ResetRequest(Strict):
    seed: int | None = Field(None, ge=0, le=2**63 - 1, description="sensor-noise seed; keep the current one if absent")


class ParameterPatch(Strict):
    values: dict[str, float | list[float] | str] = Field(min_length=1, description="parameter path -> value")


class EffectRequest(Strict):
    joint: str | None = None
    params: dict[str, float] = Field(default_factory=dict)


class FaultRequest(Strict):
    kind: Literal["sensor_stuck", "sensor_noisy", "sensor_offset", "spool_stuck", "leak", "hose_burst", "supply_sag"]
    joint: str | None = Field(None, description="joint (not for supply_sag)")
    value: float | None = Field(None, ge=-20.0, le=20.0, description="sensor_stuck: reported voltage (V)")
    std: float | None = Field(None, ge=0.0, le=5.0, description="sensor_noisy: noise standard deviation (V)")
    offset: float | None = Field(None, ge=-10.0, le=10.0, description="sensor_offset: voltage offset (V)")
    position: float | None = Field(None, ge=-1.0, le=1.0, description="spool_stuck: spool position (stroke fraction)")
    coefficient: float | None = Field(None, ge=0.0, le=1e-8, description="leak: laminar leak to tank (m^3/(s Pa))")
    chamber: Literal["a", "b", "both"] | None = Field(None, description="leak: which chamber")
    flow_coefficient: float | None = Field(None, ge=0.0, le=1e-3, description="hose_burst: orifice to tank (m^3/s/sqrt(Pa))")
    factor: float | None = Field(None, gt=0.0, le=1.0, description="supply_sag: supply pressure multiplier")

    def params(self) -> dict:
        d = self.model_dump(exclude={"kind", "joint"}, exclude_none=True)
        if self.kind == "sensor_stuck" and "value" not in d:
            raise ValueError("sensor_stuck needs value (V)")
        return d


class RecordingRequest(Strict):
    name: str | None = Field(None, min_length=1, max_length=80, pattern=r"^[A-Za-z0-9_.-]+$")
    format: Literal["csv", "parquet"] = Field("csv", description="csv: the dataset CSV; parquet: one float64 column "
                                                                  "per dataset column, units in the schema metadata")


class LatenessStats(BaseModel):
    p50: float | None
    p99: float | None
    p999: float | None
    max: float | None
    window_ticks: int


class LoopStats(BaseModel):
    rate_hz: float
    ticks: int
    overruns: int
    resyncs: int
    watchdog_trips: int
    lateness_us: LatenessStats
    realtime_priority: bool


class JointState(BaseModel):
    angle: float = Field(description="measured angle (rad); true angle for joints without a sensor")
    sensor_voltage: float | None = Field(description="potentiometer voltage (V), null without a sensor")
    command_voltage: float = Field(description="voltage applied to the valve this tick (V)")
    requested_voltage: float = Field(description="last commanded voltage (V), before watchdog/E-STOP")
    pressure_a: float = Field(description="cap-side / A chamber pressure (Pa, gauge)")
    pressure_b: float = Field(description="rod-side / B chamber pressure (Pa, gauge)")
    velocity: float = Field(description="joint velocity (rad/s)")
    spool: float = Field(description="spool position (stroke fraction)")
    sensed: bool
    watchdog: bool = Field(description="true while the command watchdog holds this valve neutral")
    source: str


class StateResponse(BaseModel):
    robot: str
    time: float = Field(description="simulated time (s)")
    tick: int
    mode: str
    estop: bool
    diverged: bool = Field(False, description="true while the diverged fault holds every valve neutral")
    supply_pressure: float = Field(description="Pa")
    joints: dict[str, JointState]
    pose: dict[str, float] = Field(description="true angle of every URDF joint (rad), for viewers")
    loop: LoopStats
    faults: list[dict]


class EngineHealth(BaseModel):
    state: str = Field(description="running | restarting | down | stopped")
    reason: str | None = Field(description="why the engine is not running")
    last_failure: str | None = Field(description="the last death or stall, also after a restart")
    restarts: int
    restart_policy: str
    pid: int | None
    down_for_s: float | None


class HealthResponse(BaseModel):
    status: str = Field(description="ok | engine_down | diverged")
    robot: str
    mode: str
    rate_hz: float
    tick: int
    uptime_s: float
    engine_alive: bool = Field(description="engine running, loop advancing and plant not diverged")
    engine: EngineHealth
    diverged: dict | None = Field(description="the latched diverged fault, or null")
    realtime_priority: bool
    realtime_note: str
    estop: bool
    can: dict | None
    auth_required: bool
    insecure: bool = Field(description="serving beyond loopback without a token (--insecure)")
    warnings: list[str] = Field(description="what is wrong or unsafe, in words")
