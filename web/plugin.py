"""The ``hydrohil.viewers`` entry point: ``hydrohil serve`` calls ``attach(service, viewer_port)``."""

from __future__ import annotations

import logging

log = logging.getLogger("hydrohil.web")


def attach(service, port: int, *, host: str = "127.0.0.1", rate_hz: float | None = None):
    """Start the browser monitor on the in-process service; returns the viewer (it has ``close()``).

    The viewer binds the loopback address: its panel can command the plant and has no token check, so
    another machine watches through ``hydrohil view --url`` (REST, token-protected) instead.
    """
    from .links import LocalLink
    from .viewer import DEFAULT_RATE_HZ, Viewer

    viewer = Viewer(LocalLink(service), host=host, port=port, rate_hz=rate_hz or DEFAULT_RATE_HZ)
    if port and viewer.port != port:
        log.warning("viewer: port %d was busy, using %d", port, viewer.port)
    log.info("browser monitor at %s (%g Hz)", viewer.url, viewer.rate_hz)
    return viewer
