"""Secure by default: loopback binds, and a token for anything that can move a valve from beyond it.

* A bind address is loopback when every address it resolves to is (127.0.0.0/8, ::1, "localhost").
* ``hydrohil serve`` refuses a non-loopback REST bind without a token unless ``--insecure`` is given;
  then it warns in the log, in ``/api/v1/health`` (``insecure``, ``warnings``) and in the viewer.
* The token comes from ``HYDROHIL_TOKEN`` or ``--token-file`` (first line); ``--token T`` still
  works but every user of the machine can read it with ``ps``, so it is warned about.
"""

from __future__ import annotations

import ipaddress
import os
import socket
from pathlib import Path

TOKEN_ENV = "HYDROHIL_TOKEN"


class SecurityError(ValueError):
    """A configuration that would expose the plant without protection (the CLI exits 2 with it)."""


def is_loopback(host: str) -> bool:
    if host in ("localhost", "localhost.localdomain"):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        pass
    try:
        infos = socket.getaddrinfo(host, None)
    except OSError:
        return False
    addrs = {i[4][0] for i in infos}
    return bool(addrs) and all(ipaddress.ip_address(a.split("%")[0]).is_loopback for a in addrs)


def resolve_token(token_arg: str | None, token_file: str | None, env=os.environ) -> tuple[str | None, list[str]]:
    """The token and the warnings its source deserves. Precedence: --token-file, HYDROHIL_TOKEN,
    --token."""
    warnings: list[str] = []
    if token_file:
        path = Path(token_file)
        try:
            text = path.read_text()
        except OSError as exc:
            raise SecurityError(f"--token-file {token_file}: {exc.strerror or exc}") from None
        token = text.splitlines()[0].strip() if text.strip() else ""
        if not token:
            raise SecurityError(f"--token-file {token_file}: the file is empty")
        try:
            if path.stat().st_mode & 0o077:
                warnings.append(f"--token-file {token_file} is readable by other users (chmod 600 it)")
        except OSError:
            pass
        return token, warnings
    if env.get(TOKEN_ENV):
        return env[TOKEN_ENV].strip(), warnings
    if token_arg:
        warnings.append("--token on the command line is visible to every user of this machine (ps); "
                        f"use {TOKEN_ENV} or --token-file")
        return token_arg, warnings
    return None, warnings


def check_bind(host: str, token: str | None, insecure: bool) -> list[str]:
    """Refuse an unprotected bind beyond loopback; with ``insecure`` accept it and say so loudly."""
    if is_loopback(host) or token:
        return []
    if not insecure:
        raise SecurityError(f"--host {host} is reachable from other machines and no token is set: anyone on the "
                            f"network could move the valves. Set a token ({TOKEN_ENV} or --token-file), bind "
                            "127.0.0.1, or pass --insecure to accept the risk")
    return [f"INSECURE: REST on {host} without a token (--insecure): anyone who can reach it can move the valves"]
