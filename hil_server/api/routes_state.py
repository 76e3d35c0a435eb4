"""Plant state: one snapshot, or a WebSocket stream at a chosen rate (the stream needs the token when
one is set). While the engine is down the snapshot answers 503 with the reason and the stream closes
with code 1013 (try again later) and the reason."""

import asyncio

from fastapi import APIRouter, Depends, Query, WebSocket, WebSocketDisconnect

from ..service import ServiceError
from .deps import get_service, websocket_token_ok
from .schemas import StateResponse, model_json

router = APIRouter(tags=["state"])


@router.get("/api/v1/state", response_model=StateResponse)
async def state(svc=Depends(get_service)):
    """Simulated time, every joint's angle, sensor and command voltage, pressures, velocity, and loop statistics."""
    return model_json(StateResponse, svc.documents.state())


@router.websocket("/api/v1/stream")
async def stream(ws: WebSocket, rate: float = Query(30.0, ge=1.0, le=250.0, description="messages per second")):
    """The /api/v1/state document pushed ``rate`` times a second."""
    svc = ws.app.state.service
    if not websocket_token_ok(ws):
        await ws.close(code=1008, reason="this stream needs the token (Authorization: Bearer <token>)")
        return
    await ws.accept()
    period = 1.0 / rate
    loop = asyncio.get_running_loop()
    next_t = loop.time()
    try:
        while True:
            try:
                doc = svc.documents.state()
            except ServiceError as exc:
                await ws.close(code=1013, reason=str(exc)[:120])
                return
            await ws.send_text(StateResponse.model_validate(doc).model_dump_json())
            next_t += period
            delay = next_t - loop.time()
            if delay < 0:
                next_t = loop.time()
                delay = 0
            await asyncio.sleep(delay)
    except (WebSocketDisconnect, RuntimeError):
        return
