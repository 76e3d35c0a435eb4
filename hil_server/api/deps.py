"""Shared dependencies: the service object and bearer-token auth for mutating endpoints, the state
stream and recording downloads."""

from __future__ import annotations

import secrets

from fastapi import Depends, HTTPException, Request, WebSocket, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

_bearer = HTTPBearer(auto_error=False)


def get_service(request: Request):
    return request.app.state.service


def require_token(request: Request, cred: HTTPAuthorizationCredentials | None = Depends(_bearer)) -> None:
    token = request.app.state.service.cfg.token
    if not token:
        return
    if cred is None:
        raise HTTPException(status.HTTP_401_UNAUTHORIZED, "this endpoint needs 'Authorization: Bearer <token>'",
                            headers={"WWW-Authenticate": "Bearer"})
    if not secrets.compare_digest(cred.credentials.encode(), token.encode()):
        raise HTTPException(status.HTTP_403_FORBIDDEN, "wrong token")


def websocket_token_ok(ws: WebSocket) -> bool:
    """A WebSocket presents the token as ``Authorization: Bearer <token>`` or, where a browser cannot
    set headers, as the ``token`` query parameter."""
    token = ws.app.state.service.cfg.token
    if not token:
        return True
    auth = ws.headers.get("authorization", "")
    given = auth[7:].strip() if auth[:7].lower() == "bearer " else ws.query_params.get("token", "")
    return bool(given) and secrets.compare_digest(given.encode(), token.encode())
