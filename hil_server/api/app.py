"""The FastAPI application around a HilService."""

from __future__ import annotations

from contextlib import asynccontextmanager

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from ..service import ServiceError
from . import (routes_commands, routes_control, routes_faults, routes_parameters, routes_recordings,
               routes_state, routes_system)


def create_app(service, *, close_on_shutdown: bool = True, start_transports: bool = False) -> FastAPI:
    """``start_transports``: start CAN and viewers on uvicorn's event loop at start-up (hydrohil serve)."""

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        if start_transports:
            try:
                await service.start_transports_async()
            except Exception as exc:
                app.state.startup_error = str(exc)
                service.close()
                raise
        yield
        await service.close_transports_async()
        if close_on_shutdown:
            service.close()  # flushes an open recording, stops the engine (also on SIGTERM)

    app = FastAPI(title="HydroHIL", version="0.1.0", lifespan=lifespan,
                  description="Hardware-in-the-loop emulator of hydraulic manipulators: a CompactFieldPoint-like "
                              "interface (command voltages in, sensor voltages and angles out) at a fixed rate.")
    app.state.service = service
    app.state.startup_error = None
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

    app.add_middleware(RequestCounter, metrics=service.metrics)
    return app


class RequestCounter:
    """Pure ASGI middleware counting requests by method, route template and status (no extra task
    per request, unlike Starlette's BaseHTTPMiddleware)."""

    def __init__(self, app, metrics):
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        status = [500]

        async def send_status(message):
            if message["type"] == "http.response.start":
                status[0] = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            route = scope.get("route")
            self.metrics.count_http(scope["method"], getattr(route, "path", "unmatched"), status[0])
