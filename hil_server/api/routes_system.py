"""Health and Prometheus metrics."""

from fastapi import APIRouter, Depends
from fastapi.responses import PlainTextResponse

from ..service.metrics import render
from .deps import get_service
from .schemas import HealthResponse, model_json

router = APIRouter(tags=["system"])


@router.get("/api/v1/health", response_model=HealthResponse)
async def health(svc=Depends(get_service)):
    """Liveness (engine process, loop progress, plant not diverged), mode, real-time priority (and why
    not), engine restarts, security warnings."""
    return model_json(HealthResponse, svc.health.document())


@router.get("/metrics", response_class=PlainTextResponse)
async def metrics(svc=Depends(get_service)):
    """Prometheus text format: loop lateness histogram, overruns, engine failures and restarts, plant
    rollbacks and divergence, shared-memory read failures, HTTP requests, CAN frames."""
    return render(svc)
