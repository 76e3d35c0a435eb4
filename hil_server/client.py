"""The REST client of a HydroHIL server, shared by the viewer (``hydrohil view``), the controllers'
experiments and the launcher. Standard library only (urllib): every installation has it.

Errors are :class:`ClientError` with the HTTP status (``None`` when the server could not be reached)
and the server's reason."""

from __future__ import annotations

import json
import urllib.error
import urllib.parse
import urllib.request


class ClientError(RuntimeError):
    def __init__(self, message: str, status: int | None = None, detail=None):
        super().__init__(message)
        self.status = status
        self.detail = detail


class HilClient:
    def __init__(self, url: str, token: str | None = None, *, timeout: float = 5.0):
        u = urllib.parse.urlsplit(url if "://" in url else f"http://{url}")
        if u.scheme not in ("http", "https"):
            raise ClientError(f"{url!r}: use http://host:port (the server's REST address)")
        self.base = f"{u.scheme}://{u.netloc}{u.path.rstrip('/')}"
        self.ws_base = f"{'wss' if u.scheme == 'https' else 'ws'}://{u.netloc}{u.path.rstrip('/')}"
        self.token = token
        self.timeout = timeout

    def headers(self) -> dict:
        return {"Authorization": f"Bearer {self.token}"} if self.token else {}

    def request(self, method: str, path: str, body: dict | None = None, *, timeout: float | None = None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method, headers=self.headers())
        req.add_header("Accept", "application/json")
        if data is not None:
            req.add_header("Content-Type", "application/json")
        try:
            with urllib.request.urlopen(req, timeout=self.timeout if timeout is None else timeout) as resp:
                raw = resp.read()
                ctype = resp.headers.get("Content-Type", "")
                return json.loads(raw or b"null") if "json" in ctype or not raw else raw
        except urllib.error.HTTPError as exc:
            try:
                detail = json.loads(exc.read()).get("detail", exc.reason)
            except Exception:  # noqa: BLE001
                detail = exc.reason
            raise ClientError(f"{method} {path}: HTTP {exc.code}: {detail}", exc.code, detail) from None
        except (urllib.error.URLError, OSError, ValueError) as exc:
            reason = getattr(exc, "reason", exc)
            raise ClientError(f"cannot reach {self.base} ({method} {path}): {reason}") from None

    # ---- the endpoints the tools use ------------------------------------------------------------
    def health(self, **kw) -> dict:
        return self.request("GET", "/api/v1/health", **kw)

    def state(self, **kw) -> dict:
        return self.request("GET", "/api/v1/state", **kw)

    def parameters(self) -> dict:
        return self.request("GET", "/api/v1/parameters")

    def set_voltages(self, voltages: dict[str, float], source: str = "rest") -> dict:
        return self.request("PUT", "/api/v1/commands", {"voltages": voltages, "source": source})

    def estop(self, engaged: bool) -> dict:
        return self.request("PUT", "/api/v1/estop", {"engaged": bool(engaged)})

    def reset(self, seed: int | None = None, *, timeout: float = 30.0) -> dict:
        return self.request("POST", "/api/v1/reset", {} if seed is None else {"seed": int(seed)}, timeout=timeout)

    def stream_url(self, rate_hz: float) -> str:
        return f"{self.ws_base}/api/v1/stream?rate={min(max(rate_hz, 1.0), 250.0):g}"
