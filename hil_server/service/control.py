"""Plant control: run mode, lockstep steps, reset. Blocking engine calls: callers run them off the
event loop (REST's sync routes run in the thread pool; the CAN bridge uses its own worker)."""

from __future__ import annotations

from ..engine import shared as S
from .config import ServiceError
from .engine_calls import engine_call


class PlantControl:
    def __init__(self, block: S.SharedBlock, engine, commands, recorder, faults):
        self.block = block
        self.engine = engine
        self.commands = commands
        self.recorder = recorder
        self.faults = faults

    @property
    def mode(self) -> str:
        return self.block.mode()

    def set_mode(self, mode: str) -> dict:
        if mode not in S.MODES:
            raise ServiceError(f"unknown mode {mode!r}; modes: {', '.join(S.MODES)}")
        return engine_call(self.engine, "mode", mode)

    def step(self, ticks: int) -> dict:
        if self.mode != "lockstep":
            raise ServiceError("step needs lockstep mode; PUT /api/v1/mode {\"mode\": \"lockstep\"} first", 409)
        if self.block.state[S.S_DIVERGED]:
            raise ServiceError("the plant diverged (fault 'diverged'); POST /api/v1/reset first", 409)
        return engine_call(self.engine, "step", int(ticks), timeout=600.0, refused=409)

    def reset(self, seed: int | None) -> dict:
        """Initial pose at time 0 with every valve neutral (commands from before must not act on the
        first tick after a reset; lockstep runs are then reproducible). Clears a diverged fault."""
        if self.recorder.current is not None:
            self.recorder.stop()  # a recording must not run across a reset of sim time
        self.commands.zero_all(S.SRC_NONE)
        out = engine_call(self.engine, "reset", seed)
        self.commands.zero_all(S.SRC_NONE)
        self.faults.clear_diverged()
        return out
