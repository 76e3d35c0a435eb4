"""hydrohil fit: calibrate nominal parameters to a measured record by output error."""


def register(sub):
    from ..ingest import add_reading_options
    from .common import add_model_options

    p = sub.add_parser(
        "fit",
        help="calibrate model parameters to a measured record (output error); writes a --params file",
        description="Fit free parameters (default: the valve flow gains of the commanded, measured joints) so "
                    "the free-run simulation matches the record; report the NRMSE fit per channel and the "
                    "parameter uncertainties. Without --free, also the parameters the robot's spec marks estimated "
                    "and the nominal ones the record identifies that no diagnosable effect could stand for; a "
                    "parameter the record does not identify (|value/sigma| < 3) is reported and kept at its nominal value. Free keys are parameter paths (joints.j2.valve.rated_flow, "
                    "joints.j2.sensor.B, supply.pressure) or effect parameters (effects.deadband.boom.width).",
    )
    p.add_argument("--robot", required=True)
    p.add_argument("data", metavar="DATA.csv", help="measured record: a dataset (.csv or .parquet), or any log file "
                   "read with the reading options below")
    p.add_argument("--free", nargs="+", metavar="PARAM", help="parameters to fit (default: valve rated_flow of each "
                   "commanded, measured joint, and the spec's estimated parameters)")
    p.add_argument("--out", required=True, metavar="PARAMS.toml", help="parameter/effect file to write")
    p.add_argument("--validation", metavar="OTHER.csv", help="also report the fit on this record (read like DATA)")
    p.add_argument("--initial-pose", choices=("auto", "spec", "data"), default="auto",
                   help="where the simulation starts: the record's first readings (auto, data: the default) or the "
                        "robot's initial positions (spec)")
    p.add_argument("--max-simulations", type=int, default=80, help="budget of model simulations (default 80)")
    p.add_argument("--workers", type=int, default=0, help="processes for the independent simulations (the flow-gain "
                   "scan, the Jacobian columns; default: CPU count; 1: all in this process; the fit is the same with any)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    add_model_options(p)
    add_reading_options(p)
    p.set_defaults(func=run)


def run(args):
    import json

    from ..identification import conditional
    from ..identification.fitting import run_fit
    from ..identification.record import load_record
    from ..ingest import options_from_args
    from . import CliError
    from .common import load_configured_robot

    if args.max_simulations < 2:
        raise CliError(f"--max-simulations {args.max_simulations}: need at least 2")
    if args.workers < 0:
        raise CliError(f"--workers {args.workers}: must be 0 (CPU count) or more")
    spec = load_configured_robot(args)
    opts = options_from_args(args)   # the validation record comes from the same logger: same options
    rec = load_record(args.data, spec, initial_pose=args.initial_pose, options=opts)
    val = load_record(args.validation, spec, initial_pose=args.initial_pose, options=opts) if args.validation else None
    res = run_fit(spec, rec, args.free, val=val, max_sims=args.max_simulations, out=args.out, workers=args.workers)
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    print(f"fitted {len(res['parameters'])} parameter(s) on {args.data} ({res['simulations']} simulations)")
    for k, p in res["parameters"].items():
        lo, hi = p["ci95"]
        if not p.get("identified", True):
            print(f"  {k} = {p['value']:.6g} (nominal): NOT identified, fitted {p['fitted']:.6g} +- {p['sigma']:.3g} "
                  f"({p.get('not_identified_because')})")
            continue
        row = next((c for c in res.get("calibration", {}).get("changes", []) if c["parameter"] == k), {})
        print(f"  {k} = {p['value']:.6g} +- {p['sigma']:.3g} (95 %: {lo:.6g} .. {hi:.6g}; was {p['initial']:.6g})"
              + ("  [at a search bound]" if p.get("at_bound") else "")
              + (f"  [{row['note']}]" if row.get("note") else "")
              + (f"  [{conditional.given(row)}]" if row.get("conditional_on") else ""))
    for k, why in res.get("calibration", {}).get("held", {}).items():
        print(f"  {k}: {why}")
    for where, fits in res["fit"].items():
        for j, ch in fits.items():
            text = ", ".join(f"{c} {v['before']:.2f} -> {v['after']:.2f} % (+-{v['spread']:.2f})" for c, v in ch.items())
            print(f"  fit on {where}, {j}: {text}")
    for note in res.get("notes", []):
        print(f"  note: {note}")
    print(f"  wrote {args.out}")
    return 0
