"""Recordings in the dataset format of ``hydrohil simulate`` (CSV, or Parquet): start, stop, list,
download (the download needs the token when one is set)."""

from fastapi import APIRouter, Depends
from fastapi.responses import FileResponse

from ..engine.process import EngineDown
from ..service import ServiceError
from .deps import get_service, require_token
from .schemas import RecordingRequest

router = APIRouter(tags=["recordings"])


def _err(exc, status):
    return ServiceError(str(exc.args[0]) if exc.args else str(exc), status)


@router.get("/api/v1/recordings")
async def list_recordings(svc=Depends(get_service)):
    return {"recordings": [r.describe() for r in svc.recorder.recordings.values()]}


@router.post("/api/v1/recordings", dependencies=[Depends(require_token)])
def start(body: RecordingRequest | None = None, svc=Depends(get_service)):
    """Start recording every tick (one at a time; 409 if one runs), as ``csv`` or ``parquet``."""
    try:
        return svc.recorder.start(body.name if body else None, body.format if body else "csv").describe()
    except (EngineDown, TimeoutError) as exc:
        raise ServiceError(f"cannot start a recording: {exc}", 503) from None
    except RuntimeError as exc:
        raise _err(exc, 409) from None


@router.post("/api/v1/recordings/stop", dependencies=[Depends(require_token)])
def stop(svc=Depends(get_service)):
    """Stop and flush the running recording; the file then holds every tick exactly once."""
    try:
        return svc.recorder.stop().describe()
    except RuntimeError as exc:
        raise _err(exc, 409) from None


@router.get("/api/v1/recordings/{rec_id}")
async def describe(rec_id: str, svc=Depends(get_service)):
    try:
        return svc.recorder.get(rec_id).describe()
    except KeyError as exc:
        raise _err(exc, 404) from None


@router.get("/api/v1/recordings/{rec_id}/data", response_class=FileResponse, dependencies=[Depends(require_token)])
def download(rec_id: str, svc=Depends(get_service)):
    """The recorded file (409 while the recording still runs)."""
    try:
        rec = svc.recorder.get(rec_id)
    except KeyError as exc:
        raise _err(exc, 404) from None
    if rec.active:
        raise _err(RuntimeError(f"recording {rec_id} is still running; stop it first"), 409)
    return FileResponse(rec.path, media_type=rec.media_type, filename=rec.path.name)
