"""The uvicorn configuration ``hydrohil serve`` runs its app under (and the tests' in-process server).

An idle keep-alive connection is held open longer than common HTTP clients keep one in their pools
(httpx and Node drop theirs after 5 s idle), so the client is always the side that closes it. With the
server's default of 5 s both ends expired together: a request sent on a connection idle for just under
5 s could meet the server's close on the wire and fail with "server disconnected" though nothing was
wrong. Holding an idle loopback connection costs one socket and no CPU.
"""

from __future__ import annotations

import uvicorn

KEEP_ALIVE_S = 75.0  # idle keep-alive connection held for (s); the client's pool expiry should be shorter


def uvicorn_config(app, *, host: str, port: int, **overrides) -> uvicorn.Config:
    """uvicorn settings for the service: no access log (the loop's neighbours pay for every line), warnings only."""
    settings = dict(host=host, port=port, log_level="warning", access_log=False, timeout_keep_alive=KEEP_ALIVE_S)
    settings.update(overrides)
    return uvicorn.Config(app, **settings)
