"""Valve commands per joint, E-STOP, and the cFP module/channel view of the same I/O."""

from fastapi import APIRouter, Depends

from .deps import get_service, require_token
from .schemas import ChannelWrite, CommandRequest, CommandResponse, EstopRequest, model_json

router = APIRouter(tags=["commands"])


@router.put("/api/v1/commands", response_model=CommandResponse, dependencies=[Depends(require_token)])
async def put_commands(body: CommandRequest, svc=Depends(get_service)):
    """Set command voltages (V) per joint. They hold until changed (no watchdog for REST commands)."""
    from ..engine.shared import SRC_REST, SRC_VIEWER

    source = SRC_VIEWER if body.source == "viewer" else SRC_REST
    return model_json(CommandResponse, {"applied": svc.set_voltages(body.voltages, source), "estop": svc.estopped})


@router.get("/api/v1/commands")
async def get_commands(svc=Depends(get_service)):
    return {"voltages": svc.command_voltages(), "estop": svc.estopped}


@router.post("/api/v1/commands/neutral", dependencies=[Depends(require_token)])
async def neutral(svc=Depends(get_service)):
    """Every valve to 0 V."""
    svc.neutral()
    return {"voltages": svc.command_voltages()}


@router.get("/api/v1/estop")
async def get_estop(svc=Depends(get_service)):
    return {"engaged": svc.estopped}


@router.put("/api/v1/estop", dependencies=[Depends(require_token)])
async def put_estop(body: EstopRequest, svc=Depends(get_service)):
    """Engage: all valves neutral, commands zeroed, until released."""
    svc.set_estop(body.engaged)
    return {"engaged": svc.estopped}


@router.get("/api/v1/cfp")
async def cfp_modules(svc=Depends(get_service)):
    """The cFP view: modules, their channels (joint, role, direction) and current values (V)."""
    snap = svc.block.snapshot()
    cmd = svc.command_voltages()
    return {"modules": {m: [{"channel": c.channel, "name": c.name, "joint": c.joint, "role": c.role,
                             "direction": c.direction, "value": svc.channel_value(c, snap, cmd)} for c in chans]
                        for m, chans in svc.channels.modules().items()}}


@router.get("/api/v1/cfp/{module}/{channel}")
async def cfp_read(module: str, channel: str, svc=Depends(get_service)):
    from ..service import ServiceError

    try:
        ch = svc.channels.get(module, channel)
    except KeyError as exc:
        raise ServiceError(str(exc.args[0]), 404) from None
    return {"module": module, "channel": channel, "joint": ch.joint, "role": ch.role, "direction": ch.direction,
            "value": svc.channel_value(ch)}


@router.put("/api/v1/cfp/{module}/{channel}", dependencies=[Depends(require_token)])
async def cfp_write(module: str, channel: str, body: ChannelWrite, svc=Depends(get_service)):
    """Write an analog output channel (amplifier input, 0..10 V) as a LabVIEW VI would."""
    return svc.write_channel(module, channel, body.value)
