"""Start and stop ``hydrohil serve`` as a child process on free ports: the one launcher the
controllers' experiments, the benchmarks and the tests use.

The server is the real console command (``python -m sim_core.cli serve``). A token goes through
``HYDROHIL_TOKEN`` in its environment, never on its command line. By default the child dies with its
parent (PR_SET_PDEATHSIG), so a killed test or experiment leaves no real-time engine behind.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from .client import ClientError, HilClient
from .security import TOKEN_ENV

ROOT = Path(__file__).resolve().parent.parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def die_with_parent() -> None:
    """preexec_fn: the child gets SIGTERM when its parent dies."""
    import ctypes

    try:
        ctypes.CDLL("libc.so.6").prctl(1, signal.SIGTERM, 0, 0, 0)   # PR_SET_PDEATHSIG
    except OSError:
        pass


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
    """``hydrohil serve --robot R --port P --can C --viewer-port V --recordings D [args]`` as a child.

    ``can``: a transport spec, ``"socketcand"`` for our server on a free port (``can_port``), or
    ``"none"``. ``workdir``: recordings go to ``workdir/recordings-PORT`` and the server's output to
    ``workdir/serve-PORT.log`` (without a workdir: ``artifacts/recordings-PORT``, output discarded).
    Ready when ``/api/v1/health`` says the engine runs."""

    def __init__(self, *args: str, robot: str = "hydrolek", can: str = "none", viewer_port: int = 0,
                 workdir: str | Path | None = None, token: str | None = None, env: dict | None = None,
                 start_timeout: float = 180.0, tie_to_parent: bool = True):
        self.robot = robot
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.token = token
        self.can_port = None
        if can == "socketcand":
            self.can_port = free_port()
            can = f"socketcand:{self.can_port}"
        elif can.startswith("socketcand:"):
            self.can_port = int(can.split(":", 1)[1].partition("@")[0] or 29536)
        self.can = can
        base = Path(workdir) if workdir else ROOT / "artifacts"
        self.recordings = base / f"recordings-{self.port}"
        self.cmd = [sys.executable, "-m", "sim_core.cli", "serve", "--robot", robot, "--port", str(self.port),
                    "--can", can, "--viewer-port", str(viewer_port), "--recordings", str(self.recordings), *args]
        child_env = dict(os.environ if env is None else env)
        child_env.pop(TOKEN_ENV, None)
        if token:
            child_env[TOKEN_ENV] = token
        self.log_path = base / f"serve-{self.port}.log" if workdir else None
        if self.log_path:
            self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self._log = open(self.log_path, "w") if self.log_path else subprocess.DEVNULL
        self.rest = HilClient(self.url, token, timeout=30.0)
        self.proc = subprocess.Popen(self.cmd, cwd=ROOT, stdout=self._log, stderr=subprocess.STDOUT, env=child_env,
                                     preexec_fn=die_with_parent if tie_to_parent else None)
        try:
            self.wait_ready(start_timeout)
        except BaseException:
            self.stop()
            raise

    def log_text(self) -> str:
        return self.log_path.read_text() if self.log_path and self.log_path.exists() else ""

    def wait_ready(self, timeout: float) -> None:
        probe = HilClient(self.url, self.token, timeout=1.0)
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.proc.poll() is not None:
                raise RuntimeError(f"hydrohil serve exited with {self.proc.returncode}"
                                   + (f"; log {self.log_path}:\n{self.log_text()[-3000:]}" if self.log_path else ""))
            try:
                if probe.health().get("engine_alive"):
                    return
            except ClientError:
                pass
            time.sleep(0.2)
        raise TimeoutError(f"hydrohil serve did not become ready within {timeout:g} s"
                           + (f"; log {self.log_path}" if self.log_path else ""))

    def stop(self, timeout: float = 30.0) -> int:
        rc = stop_process(self.proc, timeout)
        if self.log_path and not self._log.closed:
            self._log.close()
        return rc

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
