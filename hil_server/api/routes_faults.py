"""Fault injection: sensor stuck/noisy/offset, spool stuck, leak, hose burst, supply sag; and the
plant's own ``diverged`` fault (listed here, cleared by reset)."""

from fastapi import APIRouter, Depends

from ..service import ServiceError
from .deps import get_service, require_token
from .schemas import FaultRequest

router = APIRouter(tags=["faults"])


@router.get("/api/v1/faults")
async def list_faults(svc=Depends(get_service)):
    return {"faults": svc.faults.listing()}


@router.post("/api/v1/faults", dependencies=[Depends(require_token)])
def inject(body: FaultRequest, svc=Depends(get_service)):
    try:
        params = body.params()
    except ValueError as exc:
        raise ServiceError(str(exc)) from None
    return svc.faults.inject(body.kind, body.joint, params)


@router.delete("/api/v1/faults/{fault_id}", dependencies=[Depends(require_token)])
def clear(fault_id: str, svc=Depends(get_service)):
    return svc.faults.clear(fault_id)


@router.delete("/api/v1/faults", dependencies=[Depends(require_token)])
def clear_all(svc=Depends(get_service)):
    svc.faults.clear_all()
    return {"faults": svc.faults.listing()}
