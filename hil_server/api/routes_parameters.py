"""Model parameters (read, patch by path) and effects (switch on/off)."""

from fastapi import APIRouter, Depends, Query

from .deps import get_service, require_token
from .schemas import EffectRequest, ParameterPatch

router = APIRouter(tags=["parameters"])


@router.get("/api/v1/parameters")
async def get_parameters(svc=Depends(get_service)):
    """Every parameter by path (e.g. joints.j2.valve.rated_flow) and the enabled effects."""
    return svc.parameters()


@router.get("/api/v1/parameters/{path}")
async def get_parameter(path: str, svc=Depends(get_service)):
    from ..service import ServiceError

    values = svc.spec.parameters()
    if path not in values:
        raise ServiceError(f"unknown parameter path {path!r}", 404)
    return {"path": path, "value": values[path]}


@router.patch("/api/v1/parameters", dependencies=[Depends(require_token)])
def patch_parameters(body: ParameterPatch, svc=Depends(get_service)):
    """Set parameters by path; all or nothing, validated (units and bounds) before the plant sees them."""
    return {"applied": svc.patch_parameters(body.values)}


@router.get("/api/v1/effects")
async def get_effects(svc=Depends(get_service)):
    return svc.effects()


@router.put("/api/v1/effects/{name}", dependencies=[Depends(require_token)])
def put_effect(name: str, body: EffectRequest, svc=Depends(get_service)):
    """Switch an effect on (or change its parameters) for a joint, or globally."""
    return svc.enable_effect(name, body.joint, body.params)


@router.delete("/api/v1/effects/{name}", dependencies=[Depends(require_token)])
def delete_effect(name: str, joint: str | None = Query(None), svc=Depends(get_service)):
    return svc.disable_effect(name, joint)
