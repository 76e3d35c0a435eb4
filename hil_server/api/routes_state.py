"""Plant state: one snapshot, or a WebSocket stream at a chosen rate."""

import asyncio

from fastapi import APIRouter, Depends, Query, WebSocket, WebSocketDisconnect

from .deps import get_service
from .schemas import StateResponse, model_json

router = APIRouter(tags=["state"])


@router.get("/api/v1/state", response_model=StateResponse)
async def state(svc=Depends(get_service)):
    """Simulated time, every joint's angle, sensor and command voltage, pressures, velocity, and loop statistics."""
    return model_json(StateResponse, svc.state())


@router.websocket("/api/v1/stream")
async def stream(ws: WebSocket, rate: float = Query(30.0, ge=1.0, le=250.0, description="messages per second")):
    """The /api/v1/state document pushed ``rate`` times a second."""
    svc = ws.app.state.service
    await ws.accept()
    period = 1.0 / rate
    loop = asyncio.get_running_loop()
    next_t = loop.time()
    try:
        while True:
            await ws.send_text(StateResponse.model_validate(svc.state()).model_dump_json())
            next_t += period
            delay = next_t - loop.time()
            if delay < 0:
                next_t = loop.time()
                delay = 0
            await asyncio.sleep(delay)
    except (WebSocketDisconnect, RuntimeError):
        return
