"""Run modes, lockstep stepping, reset. Sync routes: FastAPI runs them in its thread pool, so a long
step never blocks the event loop that serves REST, WebSockets and CAN."""

from fastapi import APIRouter, Depends

from .deps import get_service, require_token
from .schemas import ModeRequest, ResetRequest, StepRequest

router = APIRouter(tags=["control"])


@router.get("/api/v1/mode")
async def get_mode(svc=Depends(get_service)):
    return {"mode": svc.control.mode}


@router.put("/api/v1/mode", dependencies=[Depends(require_token)])
def put_mode(body: ModeRequest, svc=Depends(get_service)):
    """realtime (fixed rate), paused, lockstep (advance only on /step) or fast (as fast as possible)."""
    return svc.control.set_mode(body.mode)


@router.post("/api/v1/step", dependencies=[Depends(require_token)])
def step(body: StepRequest, svc=Depends(get_service)):
    """Advance exactly ``ticks`` ticks (lockstep mode only, else 409)."""
    return svc.control.step(body.ticks)


@router.post("/api/v1/reset", dependencies=[Depends(require_token)])
def reset(body: ResetRequest | None = None, svc=Depends(get_service)):
    """Back to the initial pose at time 0, every valve neutral (an active recording is closed first);
    clears the ``diverged`` fault."""
    return svc.control.reset(body.seed if body else None)
