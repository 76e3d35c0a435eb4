"""One mapping from engine outcomes to the service's refusals (used by every part that asks the engine)."""

from __future__ import annotations

from ..engine.process import EngineDown, EngineError
from .config import ServiceError


def engine_call(engine, op: str, *args, timeout: float = 60.0, refused: int = 422):
    """``engine.request(op, *args)``: a refusal by the engine -> ``refused`` (4xx) with its reason; an
    engine that is down or does not answer -> 503."""
    try:
        return engine.request(op, *args, timeout=timeout)
    except EngineError as exc:
        raise ServiceError(str(exc), refused) from None
    except (EngineDown, TimeoutError, OSError, EOFError) as exc:
        raise ServiceError(str(exc), 503) from None
