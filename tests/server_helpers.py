"""A real ``hydrohil serve`` (uvicorn, engine process, transports) for tests: the package's launcher
(:mod:`hil_server.launcher`) with an httpx client on top."""

from __future__ import annotations

import httpx

from hil_server import launcher
from hil_server.launcher import ROOT, die_with_parent, free_port, stop_process  # noqa: F401 - re-exported for tests


class ServerProcess(launcher.ServerProcess):
    """``hydrohil serve`` as a subprocess, ready when its engine runs; with ``tmp_path`` its
    recordings and log (``log_path``) go there."""

    def __init__(self, *args, robot="hydrolek", can="none", viewer_port=0, tmp_path=None, token=None, extra=(),
                 env=None):
        super().__init__(*args, *extra, robot=robot, can=can, viewer_port=viewer_port, workdir=tmp_path, token=token,
                         env=env)

    def headers(self) -> dict:
        return {"Authorization": f"Bearer {self.token}"} if self.token else {}

    def client(self, **kw) -> httpx.Client:
        return httpx.Client(base_url=self.url, headers=self.headers(), timeout=30.0, **kw)

    def terminate(self, timeout=30.0) -> int:
        return self.stop(timeout)

    close = terminate
