"""hydrohil diagnose: name what the model gets wrong on a measured record and write the extended model."""


def register(sub):
    from ..ingest import add_reading_options
    from .common import add_command_hold_option, add_model_options

    p = sub.add_parser(
        "diagnose",
        help="find the effect the model lacks in measured data: diagnosis.json, report, extended.toml",
        description="Calibrate the nominal model to a measured record, fit every effect of the bank as an "
                    "extension, accept those that raise the validation fit beyond the noise, and write "
                    "DIR/diagnosis.json, DIR/report.html and DIR/extended.toml (a --params file).",
    )
    p.add_argument("--robot", required=True)
    p.add_argument("data", metavar="DATA.csv", help="measured record: a dataset (.csv or .parquet: time, u_<joint>, "
                   "q_<joint>, p_<joint>_a/b), or any log file read with the reading options below")
    p.add_argument("--validation", metavar="OTHER.csv",
                   help="separate validation record, read like DATA (default: the last 40 %% of DATA)")
    p.add_argument("--report", required=True, metavar="DIR", help="output directory")
    p.add_argument("--format", choices=("html", "md"), default="html", help="report format (default html)")
    p.add_argument("--workers", type=int, default=0, help="parallel processes for the candidate fits (default: CPU count; "
                   "with --backend ray: candidate fits in flight, default the cluster's CPUs)")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="where the candidate fits run: a local process pool (default) or Ray tasks "
                        "(pip install 'hydrohil[ray]')")
    p.add_argument("--address", metavar="ADDR", help="with --backend ray: the Ray cluster (host:port, or 'auto' for the "
                   "one started on this machine with 'ray start --head'); default: a new local Ray instance")
    p.add_argument("--effects", nargs="+", metavar="NAME", help="restrict the candidate bank to these effects")
    p.add_argument("--initial-pose", choices=("auto", "spec", "data"), default="auto",
                   help="where the simulation starts: the record's first readings (auto, data: the default; a sensor "
                        "offset is then told from the start pose by what depends on the true pose) or the robot's "
                        "initial positions (spec: the arm is known to start there, e.g. homed)")
    add_command_hold_option(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_model_options(p)
    add_reading_options(p)
    p.set_defaults(func=run)


def run(args):
    import sys

    from ..effects import EFFECTS
    from ..identification import beyond_range, command_hold, conditional, detectability, diagnosis, report
    from ..identification.decision import THRESHOLD_POINTS
    from ..identification.record import load_record
    from ..ingest import options_from_args
    from . import CliError
    from .common import load_configured_robot

    if args.workers < 0:
        raise CliError(f"--workers {args.workers}: must be 0 (CPU count) or more")
    if args.effects:
        bad = [e for e in args.effects if e not in EFFECTS]
        if bad:
            raise CliError(f"--effects: unknown effect(s) {', '.join(bad)}; effects: {', '.join(EFFECTS)}")
    spec = load_configured_robot(args)
    opts = options_from_args(args)   # the validation record comes from the same logger: same options
    rec = load_record(args.data, spec, initial_pose=args.initial_pose, options=opts)
    val = load_record(args.validation, spec, initial_pose=args.initial_pose, options=opts) if args.validation else None
    log = (lambda msg: None) if args.quiet else (lambda msg: print(msg, file=sys.stderr))
    backend = None
    if args.backend == "ray":
        from ..backends import BackendError, open_backend

        try:
            backend = open_backend("ray", address=args.address, workers=args.workers)
        except BackendError as exc:
            raise CliError(str(exc)) from None
        log(f"candidate fits on {backend.describe()}")
    elif args.address:
        raise CliError("--address is for --backend ray")
    if args.format == "html":
        report.preload()             # the figures' library, imported while the diagnosis starts on one core
    try:
        d = diagnosis.run(spec, rec, val, workers=args.workers, progress=not args.quiet and sys.stderr.isatty(),
                          log=log, effects=args.effects, backend=backend, command_hold=args.command_hold)
    finally:
        if backend is not None:
            backend.close()
    paths = report.write(d, args.report, spec, fmt=args.format, workers=args.workers)
    print(f"{d.verdict}: {args.data} on {spec.name} ({d.timings.get('total', 0):.1f} s)")
    if d.split_moved or d.split_kept:
        print(f"  validated on: {d.split_moved or d.split_kept}")
    for s in d.selected:
        params = ", ".join(f"{k}={v:.4g}" for k, v in s["params"].items())
        flag = f"; ambiguous with {s['runner_up']['effect']} ({s['decided_by']})" if s.get("ambiguous") else ""
        more = [r["effect"] + (f" on {r['joint']}" if r["joint"] and r["joint"] != s["joint"] else "")
                for r in s.get("rivals", [])[1:]]
        flag += f"; as close: {', '.join(more)}" if more else ""
        print(f"  {s['effect']}" + (f" on {s['joint']}" if s["joint"] else "") + f": {params}  gain {s['gain']:+.2f} points{flag}")
        for line in beyond_range.describe(s):
            print(f"    {line}")
        for name, h in s.get("held_at_default", {}).items():
            print(f"    {name} held at its default {h['value']:g}: the record does not show it apart from {next(iter(s['params']))}")
        for line in conditional.describe(s) + command_hold.describe(s):
            print(f"    {line}")
        for row in d.detectable:
            if row.get("named") and (row["effect"], row["joint"]) == (s["effect"], s["joint"]):
                print(f"    the record shows it from about {detectability.magnitude(row, row['shows_from'])}"
                      f"{detectability.from_spec(row)} (estimated, on the model without it)"
                      if row["shows_from"] is not None else
                      "    the estimate of what the record shows does not reach it within its range (estimated, on the "
                      "model without it)")
    hold = d.closed_loop.get("command_hold")
    if hold and (hold["replay"] != command_hold.HELD or "revisited" in hold):
        print(f"  command between samples: {command_hold.said(hold)}")
    for k, r in d.calibration.get("refitted_with_effects", {}).items():
        v, n = r["value"], r["nominal"]
        if n is not None and v is not None and v != n:
            print(f"  calibrated with {'them' if len(d.selected) > 1 else 'it'}: {k} = {v:.6g} (nominal {n:.6g}) "
                  f"{conditional.given(r)}".rstrip())
    for line in beyond_range.found(d.calibration):
        print(f"  calibrated beyond a declared range: {line}")
    for why in (d.unexplained or {}).get("because", []):
        print(f"  unexplained: {why}")
    for cause in (d.unexplained or {}).get("record_causes", []):
        print(f"  in the record: {cause}")
    for spot in d.calibration.get("blind_spots", []):
        print(f"  not testable: {spot}")
    others = [row for row in d.detectable if not row.get("named")]
    for row in others:
        if row["shows_from"] is None:
            print(f"  cannot show: {detectability.describe(row, THRESHOLD_POINTS)}")
    shows = [detectability.describe(row, THRESHOLD_POINTS) for row in others if row["shows_from"] is not None]
    if shows:
        print(f"  would show (estimated): {'; '.join(shows)}")
    for j, f in d.baseline_fits.items():
        if f.get("excited", True):
            print(f"  fit {j}: {f['angle']:.2f} % -> {d.extended_fits[j]['angle']:.2f} %")
    for key in ("json", "report", "toml"):
        print(f"  wrote {paths[key]}")
    return 0
