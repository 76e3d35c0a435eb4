"""Real parts for the browser-monitor tests: an in-process HydroHIL server (HilService + uvicorn +
the viewer plugin loaded through its entry point), a websocket probe that reads what viser sends
to a browser, headless Chromium, and screenshot arithmetic."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from server_helpers import ROOT, die_with_parent, free_port, stop_process  # noqa: F401 - free_port: for the web tests

ARTIFACTS = ROOT / "artifacts"
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--no-first-run"]
VIEWPORT = {"width": 1280, "height": 800}
# ms: the first start of a freshly installed Chromium on a loaded 2-core machine may take longer than
# Playwright's default 30 s (a fresh CI clone once errored every test of the monitor's module in its
# browser fixture; its log was not kept, and a slow first start is the likeliest cause)
LAUNCH_TIMEOUT_MS = 180_000


def artifacts_dir() -> Path:
    d = ARTIFACTS / "browser"
    d.mkdir(parents=True, exist_ok=True)
    return d


def get_or_none(url: str):
    """GET ``url``; None while nothing answers there (a server still starting)."""
    import httpx

    try:
        return httpx.get(url, timeout=5)
    except httpx.HTTPError:
        return None


def wait_for(pred, timeout: float, what: str, interval: float = 0.05):
    end = time.monotonic() + timeout
    while True:
        v = pred()
        if v:
            return v
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(interval)


# ---- servers ----------------------------------------------------------------------------------------
class InProcessServer:
    """HilService + real uvicorn in a thread; ``start_transports`` loads the viewer plugin exactly as
    ``hydrohil serve`` does (entry point group ``hydrohil.viewers``)."""

    def __init__(self, robot: str, tmp: Path, *, viewer: bool = True, token: str | None = None, **config):
        import uvicorn

        from hil_server.api.app import create_app
        from hil_server.api.http_server import uvicorn_config
        from hil_server.service import HilService, ServiceConfig

        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.token = token
        # as `hydrohil serve` does: the process's threads hand the GIL over every 0.5 ms
        self._switch = sys.getswitchinterval()
        sys.setswitchinterval(0.0005)
        cfg = ServiceConfig(robot=robot, can=None, port=self.port, viewer_port=free_port() if viewer else None,
                            recordings_dir=str(tmp / "recordings"), token=token, **config)
        self.svc = HilService(cfg)
        try:
            self.svc.start_transports()
            if viewer:
                if not self.svc.plugins:
                    raise AssertionError("the viewer plugin did not load")
                self.viewer = self.svc.plugins[0].wait(90)  # the plugin builds its viewer in the background
            else:
                self.viewer = None
            self.server = uvicorn.Server(uvicorn_config(create_app(self.svc, close_on_shutdown=False), host="127.0.0.1",
                                                       port=self.port))
            self.thread = threading.Thread(target=self.server.run, daemon=True)
            self.thread.start()
            wait_for(lambda: self.server.started, 30, "uvicorn to start")
            wait_for(lambda: self.svc.documents.state()["tick"] > 50, 60, "the engine to run")
        except BaseException:
            self.svc.close()
            sys.setswitchinterval(self._switch)
            raise

    def headers(self) -> dict:
        return {"Authorization": f"Bearer {self.token}"} if self.token else {}

    def close(self) -> None:
        self.server.should_exit = True
        self.thread.join(10)
        self.svc.close()
        sys.setswitchinterval(self._switch)


class ViewProcess:
    """``hydrohil view --url ...`` as a subprocess."""

    def __init__(self, url: str, tmp: Path, *, token: str | None = None):
        self.port = free_port()
        cmd = [sys.executable, "-m", "sim_core.cli", "view", "--url", url, "--port", str(self.port)]
        env = {k: v for k, v in os.environ.items() if k != "HYDROHIL_TOKEN"}
        if token:
            env["HYDROHIL_TOKEN"] = token     # not on the command line, where ps shows it
        self.log_path = tmp / f"view-{self.port}.log"
        self.log = open(self.log_path, "w")
        self.proc = subprocess.Popen(cmd, cwd=ROOT, stdout=self.log, stderr=subprocess.STDOUT, env=env,
                                     preexec_fn=die_with_parent)

        def ready():
            if self.proc.poll() is not None:
                raise AssertionError(f"hydrohil view exited ({self.proc.returncode}):\n{self.log_path.read_text()}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.5):
                    return True
            except OSError:
                return False

        try:
            wait_for(ready, 60, "hydrohil view", interval=0.2)
        except BaseException:
            self.close()
            raise

    def close(self) -> int:
        rc = stop_process(self.proc)
        self.log.close()
        return rc


# ---- what viser sends a browser ------------------------------------------------------------------------
def decode_viser_frame(buf: bytes) -> list[dict]:
    """Messages of one viser websocket frame (viser 1.x wire format: two u64 lengths, zstd(msgpack),
    8-byte aligned raw buffers that numpy fields point to by ``__binary_index``)."""
    import msgspec
    import zstandard

    n_inner = int.from_bytes(buf[0:8], "little")
    n_comp = int.from_bytes(buf[8:16], "little")
    doc = msgspec.msgpack.decode(zstandard.ZstdDecompressor().decompress(buf[16:16 + n_comp], max_output_size=n_inner))
    bufs, off = [], 16 + n_comp
    for n in doc.get("binaryBufferLengths", ()):
        off += (8 - off % 8) % 8
        bufs.append(buf[off:off + n])
        off += n

    def resolve(x):
        if isinstance(x, dict):
            if "__binary_index" in x:
                return np.frombuffer(bufs[x["__binary_index"]], dtype=np.dtype(x.get("dtype", "<f4")))
            return {k: resolve(v) for k, v in x.items()}
        if isinstance(x, list):
            return [resolve(v) for v in x]
        return x

    return [resolve(m) for m in doc["messages"]]


WINDOW_S = 3.0  # measuring window of the frame-rate checks


def frame_rate(probe, node: str, t0: float, t1: float) -> tuple[float, list]:
    """Orientation messages of one scene node between t0 and t1: (per second, the messages)."""
    msgs = [m for t, m in probe.of_type("SetOrientationMessage", name=node) if t0 <= t <= t1]
    return len(msgs) / (t1 - t0), msgs


class ViserProbe:
    """A websocket client that connects like a browser and records every message with its arrival time."""

    def __init__(self, port: int):
        import viser
        from websockets.sync.client import connect

        self.ws = connect(f"ws://127.0.0.1:{port}", subprotocols=[f"viser-v{viser.__version__}"], max_size=None,
                          open_timeout=10)
        self.messages: list[tuple[float, dict]] = []
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self._stop.is_set():
            try:
                raw = self.ws.recv(timeout=0.5)
            except TimeoutError:
                continue
            except Exception:  # noqa: BLE001 - closed
                return
            t = time.monotonic()
            if isinstance(raw, bytes):
                for m in decode_viser_frame(raw):
                    self.messages.append((t, m))

    def of_type(self, kind: str, since: float = 0.0, name: str | None = None) -> list[tuple[float, dict]]:
        return [(t, m) for t, m in list(self.messages)
                if m.get("type") == kind and t >= since and (name is None or m.get("name") == name)]

    def close(self):
        self._stop.set()
        try:
            self.ws.close()
        except Exception:  # noqa: BLE001
            pass
        self.thread.join(5)


# ---- browser ----------------------------------------------------------------------------------------
def require_chromium():
    """Skip without /usr/bin/chromium, unless HYDROHIL_REQUIRE_BROWSER=1 (CI): then fail."""
    if os.path.exists(CHROMIUM):
        return
    msg = f"{CHROMIUM} not found (apt-get install -y chromium)"
    if os.environ.get("HYDROHIL_REQUIRE_BROWSER") == "1":
        pytest.fail(msg + "; HYDROHIL_REQUIRE_BROWSER=1 requires the browser tests to run")
    pytest.skip(msg)


def open_page(browser, url: str):
    page = browser.new_page(viewport=VIEWPORT)
    page.goto(url, timeout=120000)  # generous: a loaded 2-core machine renders software WebGL slowly
    page.wait_for_selector("text=E-STOP", timeout=120000)
    return page


def screenshot(page, path: Path) -> np.ndarray:
    page.screenshot(path=str(path), timeout=90000)  # software WebGL on a busy 2-core machine can be slow
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB")).astype(np.int16)


def changed(a: np.ndarray, b: np.ndarray, threshold: int = 40) -> np.ndarray:
    """Pixels whose colour differs clearly (sum of absolute RGB differences)."""
    return np.abs(a - b).sum(axis=2) > threshold


def solid(mask: np.ndarray) -> np.ndarray:
    """``mask`` without its parts under 3 pixels wide (a binary opening by a 3 x 3 square): a thing
    drawn somewhere stays, an edge or a ground-grid line re-rasterised a pixel over between two
    pictures goes (seen: one grid line across the harvester's canvas, 0.7 % of it)."""
    from scipy.ndimage import binary_opening

    return binary_opening(mask, structure=np.ones((3, 3), dtype=bool))


def project(points: np.ndarray, camera) -> np.ndarray:
    """Pixel coordinates (u, v) of world points seen by a viser client's camera (OpenCV convention:
    +z forward, +y down; vertical field of view ``fov``)."""
    import viser.transforms as tf

    R = tf.SO3(np.asarray(camera.wxyz)).as_matrix()
    pc = (np.asarray(points) - np.asarray(camera.position)) @ R  # world -> camera: R^T (p - t)
    w, h = camera.image_width, camera.image_height
    f = 0.5 * h / np.tan(0.5 * camera.fov)
    return np.stack([w / 2 + f * pc[:, 0] / pc[:, 2], h / 2 + f * pc[:, 1] / pc[:, 2]], axis=1)


def region_mask(shape, uv: np.ndarray, margin: int) -> np.ndarray:
    """Boolean image mask of the bounding box of pixel points, grown by ``margin``, clipped to the image."""
    h, w = shape[:2]
    x0, y0 = np.floor(uv.min(axis=0)).astype(int) - margin
    x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + margin
    m = np.zeros((h, w), dtype=bool)
    m[max(y0, 0):min(y1, h), max(x0, 0):min(x1, w)] = True
    return m


def settled_screenshot(page, path: Path, mask: np.ndarray, *, timeout: float = 60.0, tol: float = 0.002,
                       interval_ms: int = 700) -> np.ndarray:
    """A screenshot once the masked part of the page stopped changing (viser fades objects in and out,
    and software WebGL draws only a few frames a second)."""
    prev = screenshot(page, path)
    end = time.monotonic() + timeout
    while True:
        page.wait_for_timeout(interval_ms)
        cur = screenshot(page, path)
        if changed(prev, cur)[mask].mean() < tol:
            return cur
        if time.monotonic() > end:
            raise AssertionError(f"{path.name}: the page did not settle within {timeout:g} s")
        prev = cur


def wait_changed(page, path: Path, before: np.ndarray, mask: np.ndarray, wait_s: float, tol: float = 0.002) -> bool:
    """Whether the masked part of the page came to differ from ``before`` within ``wait_s`` seconds."""
    end = time.monotonic() + wait_s
    while True:
        if changed(before, screenshot(page, path))[mask].mean() >= tol:
            return True
        if time.monotonic() > end:
            return False
        page.wait_for_timeout(300)


def dismiss_notifications(page, wait_ms: int = 10000) -> None:
    """Close viser's toasts (e.g. 'Software WebGL rendering detected', which comes a few seconds after
    the page) so they do not cover the scene in screenshots."""
    toasts = page.locator(".mantine-Notification-root")
    try:
        toasts.first.wait_for(state="visible", timeout=wait_ms)
    except Exception:  # noqa: BLE001 - no toast (a hardware-accelerated browser)
        return
    end = time.monotonic() + 15.0
    while toasts.count() and time.monotonic() < end:
        try:
            toasts.first.locator("button").first.click(timeout=2000)
        except Exception:  # noqa: BLE001 - it moved or went away meanwhile
            pass
        page.wait_for_timeout(500)
