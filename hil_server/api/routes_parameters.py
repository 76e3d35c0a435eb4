"""Model parameters (read, patch by path) and effects (switch on/off)."""

from fastapi import APIRouter, Depends, Query

from .deps import get_service, require_token
from .schemas import EffectRequest, ParameterPatch

router = APIRouter(tags=["parameters"])


@router.get("/api/v1/parameters")
async def get_parameters(svc=Depends(get_service)):
    """Every parameter by path (e.g. joints.j2.valve.rated_flow) and the enabled effects."""
    return svc.params.parameters()


@router.get("/api/v1/parameters/{path}")
async def get_parameter(path: str, svc=Depends(get_service)):
    return {"path": path, "value": svc.params.value(path)}


@router.patch("/api/v1/parameters", dependencies=[Depends(require_token)])
def patch_parameters(body: ParameterPatch, svc=Depends(get_service)):
    """Set parameters by path; all or nothing, validated (units and bounds) before the plant sees them."""
    return {"applied": svc.params.patch(body.values)}


@router.get("/api/v1/effects")
async def get_effects(svc=Depends(get_service)):
    return svc.params.effects()


@router.put("/api/v1/effects/{name}", dependencies=[Depends(require_token)])
def put_effect(name: str, body: EffectRequest, svc=Depends(get_service)):
    """Switch an effect on (or change its parameters) for a joint, or globally."""
    return svc.params.enable_effect(name, body.joint, body.params)


@router.delete("/api/v1/effects/{name}", dependencies=[Depends(require_token)])
def delete_effect(name: str, joint: str | None = Query(None), svc=Depends(get_service)):
    return svc.params.disable_effect(name, joint)
