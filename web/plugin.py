"""The ``hydrohil.viewers`` entry point: ``hydrohil serve`` calls ``attach(service, viewer_port)``."""

from __future__ import annotations

import logging
import threading

log = logging.getLogger("hydrohil.web")


class ViewerPlugin:
    """The browser monitor of an in-process service, started in the background.

    ``hydrohil serve`` calls plugins while its event loop starts; building the viewer (imports of
    viser/trimesh, the scene, the panel) takes a few seconds, so it happens in a thread of its own and
    REST and CAN come up meanwhile. :meth:`wait` returns the running :class:`web.viewer.Viewer`.
    """

    def __init__(self, service, port: int, *, host: str | None = None, rate_hz: float | None = None):
        host = host or getattr(service.cfg, "viewer_host", "127.0.0.1")
        self.requested_port = port
        self.viewer = None
        self.error: BaseException | None = None
        self._lock = threading.Lock()
        self._closed = False
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._build, args=(service, port, host, rate_hz),
                                        name="hydrohil-viewer-start", daemon=True)
        self._thread.start()

    def _build(self, service, port, host, rate_hz) -> None:
        try:
            from .links import LocalLink
            from .viewer import DEFAULT_RATE_HZ, Viewer

            viewer = Viewer(LocalLink(service), host=host, port=port, rate_hz=rate_hz or DEFAULT_RATE_HZ)
            with self._lock:
                if self._closed:  # the service stopped while the viewer was being built
                    viewer.close()
                    return
                self.viewer = viewer
            if port and viewer.port != port:
                log.warning("viewer: port %d was busy, using %d", port, viewer.port)
            log.info("browser monitor at %s (%g Hz)", viewer.url, viewer.rate_hz)
        except Exception as exc:  # noqa: BLE001 - the plant keeps running without its viewer
            self.error = exc
            log.error("viewer: could not start: %s", exc, exc_info=True)
        finally:
            self._ready.set()

    def wait(self, timeout: float = 60.0):
        """The running viewer (raises if it failed to start or is not up within ``timeout`` s)."""
        if not self._ready.wait(timeout):
            raise TimeoutError(f"the viewer did not start within {timeout:g} s")
        if self.viewer is None:
            raise RuntimeError(f"the viewer did not start: {self.error}")
        return self.viewer

    def close(self) -> None:
        with self._lock:
            self._closed = True
            viewer, self.viewer = self.viewer, None
        if viewer is not None:
            viewer.close()
        else:
            self._thread.join(timeout=30.0)  # a build under way closes its own viewer


def attach(service, port: int, *, host: str | None = None, rate_hz: float | None = None) -> ViewerPlugin:
    """Start the browser monitor on the in-process service; returns at once (see :class:`ViewerPlugin`).

    The viewer binds ``--viewer-host`` (loopback by default). Beyond loopback its panel commands only
    for a browser that entered the service's token; its WebSocket refuses foreign Origins.
    """
    return ViewerPlugin(service, port, host=host, rate_hz=rate_hz)
