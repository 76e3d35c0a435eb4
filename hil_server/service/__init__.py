"""The HIL service, split by responsibility (see :mod:`.hil_service` for the parts)."""

from .config import ServiceConfig, ServiceError
from .hil_service import HilService

__all__ = ["HilService", "ServiceConfig", "ServiceError"]
