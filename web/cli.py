"""hydrohil view: the browser monitor attached to a running server through its REST API."""

from __future__ import annotations

import logging


def register(sub):
    p = sub.add_parser("view", help="browser monitor and operator panel for a running HydroHIL server "
                                    "(REST + WebSocket)")
    p.add_argument("--url", default="http://127.0.0.1:8000", help="the server's REST address (default %(default)s)")
    p.add_argument("--port", type=int, default=8080, help="port of this monitor's web page (default %(default)s)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address this monitor binds (default loopback; beyond it a browser must enter the token "
                        "before the panel commands)")
    p.add_argument("--token", help="bearer token of the server (visible in ps: prefer HYDROHIL_TOKEN or --token-file)")
    p.add_argument("--token-file", metavar="FILE", help="read the server's bearer token from the first line of FILE")
    p.add_argument("--robot", help="the server's robot when it is not built-in: a directory holding robot.toml, or "
                                   "a robot.toml path (default: the built-in robot the server names)")
    p.add_argument("--rate", type=float, default=None, help="render rate in Hz (default 40)")
    p.add_argument("--log-level", default="info")
    p.set_defaults(func=run)


def run(args) -> int:
    import signal
    import sys
    import threading

    from sim_core.cli import CliError

    from hil_server.security import SecurityError, is_loopback, resolve_token

    from .links import LinkError, RemoteLink
    from .viewer import DEFAULT_RATE_HZ, Viewer

    logging.basicConfig(level=getattr(logging, args.log_level.upper(), logging.INFO),
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    log = logging.getLogger("hydrohil.view")
    # stream reader, render thread and viser's event loop share the GIL: hand it over every 0.5 ms
    # (as hydrohil serve does) rather than every 5 ms
    sys.setswitchinterval(0.0005)
    rate = args.rate or DEFAULT_RATE_HZ
    try:
        token, warnings = resolve_token(args.token, args.token_file)
    except SecurityError as exc:
        raise CliError(str(exc)) from None
    if not is_loopback(args.host):
        warnings.append(f"monitor on {args.host}: a browser must enter the token before its panel commands"
                        + ("" if token else " (no token given: read-only for everyone)"))
    for w in warnings:
        log.warning("%s", w)
    try:
        # the stream runs faster than the renderer, so (almost) every frame has a fresh state
        link = RemoteLink(args.url, token, rate_hz=min(1.5 * rate, 250.0), robot=args.robot)
    except LinkError as exc:
        raise CliError(str(exc)) from None
    try:
        viewer = Viewer(link, host=args.host, port=args.port, rate_hz=rate)
    except Exception:
        link.close()
        raise
    log.info("monitoring %s (robot %s) at %s%s", link.base, link.robot, viewer.url,
             "" if link.can_command else " read-only: the server needs --token for commands")
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    try:
        while not done.wait(0.5):
            pass
    finally:
        viewer.close()
    return 0
