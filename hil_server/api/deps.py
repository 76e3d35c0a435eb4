"""Shared dependencies: the service object and bearer-token auth for mutating endpoints."""

from __future__ import annotations

import secrets

from fastapi import Depends, HTTPException, Request, status
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
    if not secrets.compare_digest(cred.credentials, token):
        raise HTTPException(status.HTTP_403_FORBIDDEN, "wrong token")
