"""Start and stop ``hydrohil serve`` subprocesses on free ports (the emulator the controllers talk to)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class EmulatorProcess:
    """``hydrohil serve --robot R --port P --can socketcand:C --viewer-port 0 --mode M ...`` as a child
    process; REST on ``rest_port`` (used only to reset between runs), CAN (socketcand) on ``can_port``."""

    def __init__(self, robot: str, *, mode: str = "lockstep", rate_hz: float = 1000.0, feedback_rate_hz: float = 100.0,
                 params: str | Path | None = None, workdir: str | Path = ".", watchdog_ms: float = 100.0,
                 start_timeout_s: float = 180.0):
        self.robot = robot
        self.mode = mode
        self.rest_port = free_port()
        self.can_port = free_port()
        self.url = f"http://127.0.0.1:{self.rest_port}"
        workdir = Path(workdir)
        workdir.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "sim_core.cli", "serve", "--robot", robot, "--port", str(self.rest_port),
               "--can", f"socketcand:{self.can_port}", "--viewer-port", "0", "--mode", mode, "--rate", f"{rate_hz:g}",
               "--feedback-rate", f"{feedback_rate_hz:g}", "--watchdog-ms", f"{watchdog_ms:g}",
               "--recordings", str(workdir / "recordings"), "--log-level", "warning"]
        if params:
            cmd += ["--params", str(params)]
        self.cmd = cmd
        self.log_path = workdir / f"serve-{robot}-{self.rest_port}.log"
        self._log = open(self.log_path, "w")
        self.proc = subprocess.Popen(cmd, stdout=self._log, stderr=subprocess.STDOUT, env=dict(os.environ))
        try:
            self._wait_ready(start_timeout_s)
        except Exception:
            self.stop()
            raise

    def _request(self, method: str, path: str, body: dict | None = None, timeout: float = 30.0) -> dict:
        data = json.dumps(body).encode() if body is not None else None
        req = urllib.request.Request(self.url + path, data=data, method=method,
                                     headers={"Content-Type": "application/json"} if data else {})
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return json.loads(r.read().decode() or "{}")

    def _wait_ready(self, timeout: float) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.proc.poll() is not None:
                raise RuntimeError(f"hydrohil serve exited with {self.proc.returncode}; log: {self.log_path}\n"
                                   + self.log_path.read_text()[-2000:])
            try:
                if self._request("GET", "/api/v1/health", timeout=1.0).get("engine_alive"):
                    return
            except (urllib.error.URLError, OSError, ValueError):
                pass
            time.sleep(0.2)
        raise TimeoutError(f"hydrohil serve did not become ready in {timeout} s; log: {self.log_path}")

    def reset(self, seed: int) -> dict:
        """Initial pose at t = 0, every valve neutral, sensor noise seeded (REST: test-harness action)."""
        return self._request("POST", "/api/v1/reset", {"seed": int(seed)})

    def state(self) -> dict:
        return self._request("GET", "/api/v1/state")

    def stop(self, timeout: float = 30.0) -> int | None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self._log.close()
        return self.proc.returncode

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
