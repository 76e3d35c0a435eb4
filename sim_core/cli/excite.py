"""hydrohil excite: a multi-level PRBS command file (CSV or Parquet) for one joint."""


def register(sub):
    from .common import ROBOT_HELP

    p = sub.add_parser("excite", help="write a multi-level PRBS input CSV for one joint (others at 0 V)")
    p.add_argument("--robot", required=True, help=ROBOT_HELP)
    p.add_argument("--joint", required=True)
    p.add_argument("--levels", type=int, default=5, help="number of voltage levels (default 5)")
    p.add_argument("--amplitude", type=float, default=5.0, help="largest |voltage| (V, default 5)")
    p.add_argument("--duration", type=float, default=60.0, help="length (s, default 60)")
    p.add_argument("--rate", type=float, default=200.0, help="sample rate (Hz, default 200 as in the harvester data)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--period", type=float, default=0.5, help="PRBS clock period (s, default 0.5)")
    p.add_argument("--no-guard", action="store_true",
                   help="do not mirror levels that the nominal model predicts would hit an end stop")
    p.add_argument("--out", required=True, metavar="IN.csv", help="input file to write (.csv or .parquet)")
    p.set_defaults(func=run)


def run(args):
    from ..dataset import write_dataset
    from ..excitation import multilevel_prbs
    from ..model.spec import load_robot
    from . import CliError

    spec = load_robot(args.robot)
    if args.joint not in spec.joint_names:
        raise CliError(f"--joint {args.joint!r}: unknown joint; joints of {spec.name}: {', '.join(spec.joint_names)}")
    t, U = multilevel_prbs(spec, args.joint, levels=args.levels, amplitude=args.amplitude, duration=args.duration,
                           rate=args.rate, seed=args.seed, period=args.period, guard=not args.no_guard)
    cols = {"time": t}
    for a, j in enumerate(spec.joint_names):
        cols[f"u_{j}"] = U[:, a]
    write_dataset(args.out, cols, spec=spec)
    print(f"wrote {args.out}: {len(t)} rows, {t[-1]:g} s at {args.rate:g} Hz, joint {args.joint}")
    return 0
