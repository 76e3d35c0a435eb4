"""hydrohil diagnose-fleet: diagnose many records (locally or on Ray) and summarise them across the fleet."""


def register(sub):
    from ..ingest import add_reading_options
    from .common import ROBOT_HELP, add_command_hold_option, add_model_options

    p = sub.add_parser(
        "diagnose-fleet",
        help="diagnose many records of one robot, on this machine or a Ray cluster: DIR/fleet.json, fleet.csv, index.html",
        description="Diagnose every RECORD like 'hydrohil diagnose' (DIR/<record>/diagnosis.json, report.html, "
                    "extended.toml), then summarise the fleet: DIR/fleet.json, DIR/fleet.csv and DIR/index.html, one row "
                    "per record and one view per effect across the records (over time when the records are dated). "
                    "A record that fails gets its error in the summary and the others go on; a re-run with the same DIR "
                    "skips the records whose bytes, robot, options and hydrohil code have not changed. Each record is "
                    "validated on its own last 40 %. Exit status 1 when a record failed.",
    )
    p.add_argument("records", nargs="+", metavar="RECORD", help="measured records (datasets, or log files read with the "
                   "reading options below)")
    p.add_argument("--robot", required=True, help=ROBOT_HELP)
    p.add_argument("--report", required=True, metavar="DIR", help="output directory (kept between runs)")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="local processes (default) or Ray tasks (pip install 'hydrohil[ray]')")
    p.add_argument("--address", metavar="ADDR", help="with --backend ray: the Ray cluster (host:port, or 'auto' for "
                   "the one started with 'ray start --head' on this machine); default: a new local Ray instance")
    p.add_argument("--workers", type=int, default=0, help="records diagnosed at once (default: the CPU count, or the "
                   "Ray cluster's CPUs); each record's candidate fits run one after another")
    p.add_argument("--format", choices=("html", "md"), default="html", help="per-record report format (default html)")
    p.add_argument("--effects", nargs="+", metavar="NAME", help="restrict the candidate bank to these effects")
    p.add_argument("--initial-pose", choices=("auto", "spec", "data"), default="auto",
                   help="where each simulation starts (see 'hydrohil diagnose')")
    p.add_argument("--date-from", default="name", metavar="name|SOURCE",
                   help="the record's date: 'name' (default: a date in the file name, e.g. crane7_2024-03-01.csv or "
                        "20240301T0600) or a file column (header name or 0-based index) whose first value is an ISO 8601 "
                        "date or Unix seconds")
    add_command_hold_option(p)
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    add_model_options(p)
    add_reading_options(p)
    p.set_defaults(func=run)


def run(args):
    import sys

    from ..backends import BackendError, open_backend
    from ..effects import EFFECTS
    from ..fleet import FleetOptions, run_fleet
    from ..ingest import options_from_args
    from . import CliError
    from .common import load_configured_robot

    if args.workers < 0:
        raise CliError(f"--workers {args.workers}: must be 0 (all CPUs) or more")
    if args.address and args.backend != "ray":
        raise CliError("--address is for --backend ray")
    if args.effects:
        bad = [e for e in args.effects if e not in EFFECTS]
        if bad:
            raise CliError(f"--effects: unknown effect(s) {', '.join(bad)}; effects: {', '.join(EFFECTS)}")
    if args.backend == "ray":     # say so now, not after reading the records
        try:
            import ray  # noqa: F401
        except ImportError:
            from ..backends import RAY_MISSING

            raise CliError(RAY_MISSING) from None
    spec = load_configured_robot(args)
    opts = FleetOptions(spec, options_from_args(args), initial_pose=args.initial_pose, effects=args.effects,
                        fmt=args.format, date_from=args.date_from, command_hold=args.command_hold)
    log = (lambda msg: None) if args.quiet else (lambda msg: print(msg, file=sys.stderr, flush=True))

    def backend():
        try:
            return open_backend(args.backend, address=args.address, workers=args.workers)
        except BackendError as exc:
            raise CliError(str(exc)) from None

    res = run_fleet(args.records, opts, args.report, backend_factory=backend, log=log)
    for r in res.rows:
        if r["status"] == "failed":
            print(f"  {r['record']}: FAILED: {r['error']}")
        else:
            named = ", ".join(e["label"] for e in r["effects"])
            print(f"  {r['record']}: {r['verdict']}" + (f" ({named})" if named else "") + f" [{r['status']}]")
    for key in ("json", "csv", "index"):
        if key in res.paths:
            print(f"  wrote {res.paths[key]}")
    return 1 if res.failed else 0
