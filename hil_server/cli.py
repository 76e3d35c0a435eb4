"""hydrohil serve / hydrohil dbc."""

from __future__ import annotations

import logging


def register_serve(sub):
    p = sub.add_parser("serve", help="run the HIL emulator: REST + CAN + browser viewer at a fixed rate")
    p.add_argument("--robot", default="mars_nd",
                   help="built-in robot name, a directory holding robot.toml, or a robot.toml path")
    p.add_argument("--host", default="127.0.0.1",
                   help="REST bind address (default loopback; beyond loopback a token is required, or --insecure)")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--can", default="socketcand:29536",
                   help="CAN transport: virtual[:channel], socketcan:<iface>, socketcand:<port>[@host], "
                        "udp_multicast[:group][@port][,hop_limit=N], none")
    p.add_argument("--viewer-port", type=int, default=8080, help="browser viewer port (0: no viewer)")
    p.add_argument("--viewer-host", default="127.0.0.1",
                   help="viewer bind address (default loopback; beyond it the panel commands only for a browser "
                        "that entered the token)")
    p.add_argument("--rate", type=float, default=1000.0, help="plant rate (Hz)")
    p.add_argument("--mode", default="realtime", choices=["realtime", "paused", "lockstep", "fast"])
    p.add_argument("--params", metavar="FILE.toml", help="parameter/effect file (e.g. a diagnosis's extended.toml)")
    p.add_argument("--token", help="bearer token (visible in ps: prefer HYDROHIL_TOKEN or --token-file)")
    p.add_argument("--token-file", metavar="FILE", help="read the bearer token from the first line of FILE")
    p.add_argument("--insecure", action="store_true",
                   help="allow a non-loopback --host without a token (warned in the log, /health and the viewer)")
    p.add_argument("--watchdog-ms", type=float, default=100.0, help="CAN command timeout per joint (ms; 0 = off)")
    p.add_argument("--alive-counter-limit", type=int, default=3,
                   help="ValveCommand counter errors in a row tolerated per joint before frames count as lost "
                        "(0: no check)")
    p.add_argument("--feedback-rate", type=float, default=100.0, help="cyclic CAN feedback rate (Hz)")
    p.add_argument("--recordings", default="recordings", help="directory for recordings")
    p.add_argument("--seed", type=int, default=0, help="sensor-noise seed")
    p.add_argument("--no-rt", action="store_true", help="do not ask for real-time priority")
    p.add_argument("--engine-restart", choices=["auto", "never"], default="auto",
                   help="after the engine dies or stalls: restart it (with backoff, at most 5 a minute) or stay down")
    p.add_argument("--stall-ms", type=float, default=100.0,
                   help="an engine loop without progress for this long is a stall (killed, reported)")
    p.add_argument("--log-level", default="info")
    p.set_defaults(func=run_serve)


def run_serve(args) -> int:
    import uvicorn

    from sim_core.cli import CliError
    from sim_core.model.spec import SpecError

    from .api.app import create_app
    from .api.http_server import uvicorn_config
    from .engine.process import EngineStartError
    from .security import SecurityError, check_bind, is_loopback, resolve_token
    from .service import HilService, ServiceConfig, ServiceError

    logging.basicConfig(level=getattr(logging, args.log_level.upper(), logging.INFO),
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    log = logging.getLogger("hydrohil.serve")
    try:
        token, warnings = resolve_token(args.token, args.token_file)
        warnings += check_bind(args.host, token, args.insecure)
    except SecurityError as exc:
        raise CliError(str(exc)) from None
    if args.viewer_port and not is_loopback(args.viewer_host):
        warnings.append(f"viewer on {args.viewer_host}: its panel is read-only for a browser until it enters the token"
                        + ("" if token else " (no token is set: read-only for everyone)"))
    if args.stall_ms < 10.0:
        raise CliError(f"--stall-ms {args.stall_ms:g}: at least 10 ms (the loop reports progress every 10 ms when idle)")
    cfg = ServiceConfig(robot=args.robot, host=args.host, port=args.port,
                        can=None if args.can in ("none", "") else args.can,
                        viewer_port=args.viewer_port or None, viewer_host=args.viewer_host, rate_hz=args.rate,
                        mode=args.mode, params=args.params, token=token, insecure=args.insecure and not token,
                        watchdog_ms=args.watchdog_ms, feedback_rate_hz=args.feedback_rate,
                        recordings_dir=args.recordings, seed=args.seed, realtime_priority=not args.no_rt,
                        engine_restart=args.engine_restart, stall_ms=args.stall_ms,
                        alive_counter_limit=args.alive_counter_limit, warnings=warnings)
    for w in warnings:
        log.warning("%s", w)
    if cfg.can:
        from .can.transports import probe_transport

        try:
            probe_transport(cfg.can)
        except (OSError, ValueError) as exc:
            raise CliError(str(exc)) from None
    try:
        svc = HilService(cfg)
    except (ServiceError, SpecError) as exc:
        raise CliError(str(exc)) from None
    except EngineStartError as exc:     # the engine's own traceback, if it sent one, goes to the log
        first, _, detail = str(exc).partition("\n")
        if detail:
            log.error("engine start-up:\n%s", detail)
        raise CliError(first) from None
    h = svc.health.document()
    log.info("robot %s at %g Hz (%s), REST http://%s:%d, CAN %s, engine restart %s", cfg.robot, cfg.rate_hz, cfg.mode,
             cfg.host, cfg.port, cfg.can or "off", cfg.engine_restart)
    if not h["realtime_priority"]:
        log.warning("loop runs without real-time priority: %s", h["realtime_note"])
    else:
        log.info("loop: %s", h["realtime_note"])
    # threads of this process (uvicorn, CAN bridge, recorder, viewer) hand the GIL over every 0.5 ms
    # instead of 5 ms: request latency no longer waits on a busy neighbour thread (research note)
    import sys

    sys.setswitchinterval(0.0005)
    app = create_app(svc, start_transports=True)
    # everything built so far lives as long as the server: keep it out of the cyclic GC, whose full
    # collections of a start-up heap took ~50-100 ms (a stalled event loop: late CAN commands, slow REST)
    import gc

    gc.collect()
    gc.freeze()
    server = uvicorn.Server(uvicorn_config(app, host=cfg.host, port=cfg.port, lifespan="on"))
    # uvicorn handles SIGTERM/SIGINT while serving (graceful shutdown: the lifespan closes the service,
    # recordings are flushed), then re-raises the signal under the handlers it found. With these no-op
    # handlers in place a clean stop exits 0 instead of dying by the signal.
    import signal

    signal.signal(signal.SIGTERM, lambda *_: None)
    signal.signal(signal.SIGINT, lambda *_: None)
    try:
        server.run()
    except SystemExit:  # uvicorn exits 3 when start-up fails; the reason is in startup_error
        if not app.state.startup_error:
            raise
    finally:
        svc.close()
    if app.state.startup_error:
        raise CliError(f"cannot start transports: {app.state.startup_error}")
    return 0


def register_dbc(sub):
    p = sub.add_parser("dbc", help="print the CAN database (DBC) of a robot")
    p.add_argument("--robot", default="mars_nd",
                   help="built-in robot name, a directory holding robot.toml, or a robot.toml path")
    p.set_defaults(func=run_dbc)


def run_dbc(args) -> int:
    from sim_core.model.spec import load_robot

    from .can.dbc import database_text

    print(database_text(load_robot(args.robot)), end="")
    return 0
