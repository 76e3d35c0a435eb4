"""Valve commands per joint, E-STOP, and the cFP module/channel view of the same I/O."""

from fastapi import APIRouter, Depends

from ..engine.shared import SRC_REST, SRC_VIEWER
from .deps import get_service, require_token
from .schemas import ChannelWrite, CommandRequest, CommandResponse, EstopRequest, model_json

router = APIRouter(tags=["commands"])


@router.put("/api/v1/commands", response_model=CommandResponse, dependencies=[Depends(require_token)])
async def put_commands(body: CommandRequest, svc=Depends(get_service)):
    """Set command voltages (V) per joint. They hold until changed (no watchdog for REST commands).
    503 while the engine is down, 409 while the plant is diverged: nothing claims a valve moved."""
    source = SRC_VIEWER if body.source == "viewer" else SRC_REST
    return model_json(CommandResponse, {"applied": svc.commands.set(body.voltages, source),
                                        "estop": svc.commands.estopped})


@router.get("/api/v1/commands")
async def get_commands(svc=Depends(get_service)):
    return {"voltages": svc.commands.voltages(), "estop": svc.commands.estopped}


@router.post("/api/v1/commands/neutral", dependencies=[Depends(require_token)])
async def neutral(svc=Depends(get_service)):
    """Every valve to 0 V."""
    svc.commands.neutral()
    return {"voltages": svc.commands.voltages()}


@router.get("/api/v1/estop")
async def get_estop(svc=Depends(get_service)):
    return {"engaged": svc.commands.estopped}


@router.put("/api/v1/estop", dependencies=[Depends(require_token)])
async def put_estop(body: EstopRequest, svc=Depends(get_service)):
    """Engage: all valves neutral, commands zeroed, until released."""
    svc.commands.set_estop(body.engaged)
    return {"engaged": svc.commands.estopped}


@router.get("/api/v1/cfp")
async def cfp_modules(svc=Depends(get_service)):
    """The cFP view: modules, their channels (joint, role, direction) and current values (V)."""
    return {"modules": svc.cfp.modules()}


@router.get("/api/v1/cfp/{module}/{channel}")
async def cfp_read(module: str, channel: str, svc=Depends(get_service)):
    return svc.cfp.describe(module, channel)


@router.put("/api/v1/cfp/{module}/{channel}", dependencies=[Depends(require_token)])
async def cfp_write(module: str, channel: str, body: ChannelWrite, svc=Depends(get_service)):
    """Write an analog output channel (amplifier input, 0..10 V) as a LabVIEW VI would."""
    return svc.cfp.write(module, channel, body.value)
