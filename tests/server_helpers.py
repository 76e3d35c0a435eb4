"""Start a real ``hydrohil serve`` (uvicorn, engine process, transports) for tests."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parent.parent


def die_with_parent() -> None:
    """Servers started by a test die with the test process (no orphans if pytest is killed)."""
    import ctypes

    try:
        ctypes.CDLL("libc.so.6").prctl(1, signal.SIGTERM, 0, 0, 0)   # PR_SET_PDEATHSIG
    except OSError:
        pass


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop_process(proc: subprocess.Popen, timeout: float = 30.0) -> int:
    """SIGTERM (a clean stop), then kill after ``timeout``; the exit status."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
    return proc.returncode


class ServerProcess:
    """``hydrohil serve`` as a subprocess (the real console command), ready when its engine runs."""

    def __init__(self, *args, robot="hydrolek", can="none", viewer_port=0, tmp_path=None, token=None, extra=()):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.token = token
        self.recordings = Path(tmp_path or ROOT / "artifacts") / f"recordings-{self.port}"
        cmd = [sys.executable, "-m", "sim_core.cli", "serve", "--robot", robot, "--port", str(self.port),
               "--can", can, "--viewer-port", str(viewer_port), "--recordings", str(self.recordings), *args, *extra]
        if token:
            cmd += ["--token", token]
        self.log_path = self.recordings.parent / f"serve-{self.port}.log" if tmp_path else None
        self.log = open(self.log_path, "w") if self.log_path else subprocess.DEVNULL
        self.proc = subprocess.Popen(cmd, cwd=ROOT, stdout=self.log, stderr=subprocess.STDOUT, preexec_fn=die_with_parent)
        self._wait_ready()

    def _wait_ready(self, timeout=120.0):
        end = time.time() + timeout
        while time.time() < end:
            if self.proc.poll() is not None:
                raise RuntimeError(f"hydrohil serve exited with {self.proc.returncode}")
            try:
                r = httpx.get(self.url + "/api/v1/health", timeout=1.0)
                if r.status_code == 200 and r.json()["engine_alive"]:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        self.stop()
        raise TimeoutError("server did not become ready")

    def headers(self) -> dict:
        return {"Authorization": f"Bearer {self.token}"} if self.token else {}

    def client(self, **kw) -> httpx.Client:
        return httpx.Client(base_url=self.url, headers=self.headers(), timeout=30.0, **kw)

    def terminate(self, timeout=30.0) -> int:
        rc = stop_process(self.proc, timeout)
        if self.log_path:
            self.log.close()
        return rc

    stop = close = terminate
