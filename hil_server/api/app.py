"""The FastAPI application around a HilService."""

from __future__ import annotations

import time
from contextlib import asynccontextmanager

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from ..service import ServiceError
from . import (routes_commands, routes_control, routes_faults, routes_parameters, routes_recordings,
               routes_state, routes_system)


def create_app(service, *, close_on_shutdown: bool = True) -> FastAPI:
    @asynccontextmanager
    async def lifespan(app: FastAPI):
        yield
        if close_on_shutdown:
            service.close()  # flushes an open recording, stops the engine (also on SIGTERM)

    app = FastAPI(title="HydroHIL", version="0.1.0", lifespan=lifespan,
                  description="Hardware-in-the-loop emulator of hydraulic manipulators: a CompactFieldPoint-like "
                              "interface (command voltages in, sensor voltages and angles out) at a fixed rate.")
    app.state.service = service
    for r in (routes_system, routes_state, routes_commands, routes_control, routes_parameters, routes_faults,
              routes_recordings):
        app.include_router(r.router)

    @app.exception_handler(ServiceError)
    async def service_error(_request: Request, exc: ServiceError):
        return JSONResponse(status_code=exc.status, content={"detail": str(exc)})

    @app.exception_handler(RequestValidationError)
    async def validation_error(_request: Request, exc: RequestValidationError):
        errors = [{"loc": list(e.get("loc", ())), "msg": e.get("msg", ""), "type": e.get("type", "")} for e in exc.errors()]
        return JSONResponse(status_code=422, content={"detail": errors})

    @app.middleware("http")
    async def count_requests(request: Request, call_next):
        response = await call_next(request)
        route = request.scope.get("route")
        service.metrics.count_http(request.method, getattr(route, "path", "unmatched"), response.status_code)
        return response

    return app
