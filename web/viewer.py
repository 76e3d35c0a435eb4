"""The viewer: a viser server, the 3D scene, the operator panel and one render thread.

The render thread wakes at ``rate_hz`` (absolute deadlines; a late frame is dropped, never caught up
in a burst), takes the latest plant state from the link (a shared-memory copy in-process, the last
WebSocket message for a remote server), draws it, and refreshes the panel every few frames. It never
waits on the plant: the plant runs in its own engine process at its own rate, and a slow browser only
makes viser drop superseded pose messages for that browser.
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np

from .origin_guard import OriginGuard
from .panel import OperatorPanel
from .scene import ArmScene

log = logging.getLogger("hydrohil.web")

DEFAULT_RATE_HZ = 40.0   # > the 30 Hz the monitor must show, with margin for a busy machine
PANEL_RATE_HZ = 5.0


class Viewer:
    def __init__(self, link, *, host: str = "127.0.0.1", port: int = 8080, rate_hz: float = DEFAULT_RATE_HZ,
                 start: bool = True):
        import viser

        if not 1.0 <= rate_hz <= 120.0:
            raise ValueError(f"viewer rate {rate_hz} Hz: must be between 1 and 120 Hz")
        self.link = link
        self.rate_hz = float(rate_hz)
        from hil_server.security import is_loopback

        self.server = viser.ViserServer(host=host, port=port, label=f"HydroHIL · {link.spec.name}", verbose=False)
        self.host = host
        self.port = self.server.get_port()
        loopback = is_loopback(host)
        try:
            self.guard = OriginGuard(self.server, loopback)
        except RuntimeError:
            self.server.stop()
            raise
        self.server.scene.set_up_direction("+z")
        self.scene = ArmScene(self.server, link.spec)
        self._frame_camera()
        self.panel = OperatorPanel(self.server, link, scene=self.scene, render_rate_hz=self.rate_hz, guard=self.guard,
                                   needs_token=not loopback)
        self.frames = 0
        self._frame_times = np.zeros(64)
        self._frame_cpu = np.zeros(64)
        self._stamps = np.zeros(64)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hydrohil-viewer", daemon=True)
        self._closed = False
        if start:
            self._thread.start()

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def _frame_camera(self) -> None:
        """Lighting, a ground grid, and a default camera that frames the robot's workspace in the part
        of a 16:10 page the panel (right, ~30 %) leaves free."""
        scene = self.server.scene
        scene.configure_environment_map("warehouse", environment_intensity=0.45)
        scene.configure_default_lights(enabled=True, cast_shadow=False)  # shadows cost a lot in software WebGL
        lo, hi = self.scene.bounds
        centre = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.2)
        fov = np.radians(45.0)
        dist = radius / np.sin(fov / 2.0) * 0.8
        direction = np.array([0.55, -1.0, 0.5])
        direction /= np.linalg.norm(direction)
        right = np.cross(-direction, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        shift = right * 0.3 * dist * np.tan(fov / 2.0) * 1.6
        cam = self.server.initial_camera
        cam.fov = fov
        cam.near = radius * 0.01
        cam.far = radius * 100.0
        cam.look_at = centre + shift
        cam.position = centre + shift + direction * dist
        g = float(np.ceil(max(hi[0] - lo[0], hi[1] - lo[1]) * 1.6 + 0.5))
        cell = 0.1 if g <= 4 else (0.5 if g <= 20 else 1.0)
        scene.add_grid("/grid", width=g, height=g, cell_size=cell, section_size=cell * 5,
                       position=(centre[0], centre[1], 0.0))

    # ---- render thread -----------------------------------------------------------------------------
    def _run(self) -> None:
        period = 1.0 / self.rate_hz
        panel_every = max(1, int(round(self.rate_hz / PANEL_RATE_HZ)))
        next_t = time.perf_counter()
        while not self._stop.is_set():
            t0 = time.perf_counter()
            c0 = time.thread_time()
            try:
                fetched = time.monotonic()
                state = self.link.latest()
                if state is not None:
                    self.scene.update(state)
                    self.panel.record(state)
                if self.frames % panel_every == 0:
                    self.panel.update(state, self.link.status(), self.stats(), fetched_at=fetched)
            except Exception:  # noqa: BLE001 - keep drawing; the plant is unaffected either way
                log.exception("viewer: frame failed")
            t1 = time.perf_counter()
            k = self.frames % len(self._stamps)
            self._frame_times[k] = t1 - t0
            self._frame_cpu[k] = time.thread_time() - c0
            self._stamps[k] = t1
            self.frames += 1
            next_t += period
            delay = next_t - time.perf_counter()
            if delay < -period:  # more than a frame behind: drop frames, keep the phase
                next_t = time.perf_counter()
                delay = 0.0
            self._stop.wait(max(delay, 0.0))

    def stats(self) -> dict:
        n = min(self.frames, len(self._stamps))
        rate = 0.0
        if n >= 2:
            s = np.sort(self._stamps[:n])
            rate = (n - 1) / max(s[-1] - s[0], 1e-9)
        return {"rate_hz": rate, "frame_ms": float(self._frame_times[:n].mean() * 1e3) if n else 0.0,
                "frame_cpu_ms": float(self._frame_cpu[:n].mean() * 1e3) if n else 0.0,
                "frames": self.frames, "clients": len(self.server.get_clients())}

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=3.0)
        try:
            self.server.stop()
        finally:
            self.link.close()
