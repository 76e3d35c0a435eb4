"""hydrohil simulate: run the plant open-loop on an input file and write the dataset (CSV or Parquet)."""


def register(sub):
    from ..ingest import add_reading_options
    from .common import ROBOT_HELP, add_model_options

    p = sub.add_parser("simulate", help="simulate an input file (time, u_<joint>) and write a dataset CSV/Parquet")
    p.add_argument("--robot", required=True, help=ROBOT_HELP)
    p.add_argument("--input", required=True, metavar="IN.csv",
                   help="commands: a dataset (.csv or .parquet) with time and u_<joint>, or any log file read with the "
                        "reading options below")
    p.add_argument("--out", required=True, metavar="OUT.csv", help="dataset to write (.csv or .parquet)")
    add_model_options(p)
    add_reading_options(p)
    p.add_argument("--noise-angle", type=float, metavar="RAD",
                   help="standard deviation of the position measurement noise (rad; m on a prismatic joint); default: the sensors' own")
    p.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")
    p.set_defaults(func=run)


def run(args):
    import math
    import sys

    from ..dataset import input_matrix, write_dataset
    from ..ingest import options_from_args, read_input
    from ..plant import Plant
    from ..simulator import Simulator
    from . import CliError
    from .common import load_configured_robot

    spec = load_configured_robot(args)
    if args.noise_angle is not None:
        if not (math.isfinite(args.noise_angle) and args.noise_angle >= 0):
            raise CliError(f"--noise-angle {args.noise_angle}: must be a non-negative number of radians")
        for j in spec.joints:
            if j.sensed:
                spec.set(f"joints.{j.name}.sensor.noise", args.noise_angle / abs(j.components["sensor"]["A"]))
    imp = read_input(args.input, spec, options_from_args(args))
    for note in imp.notes:
        print(f"{args.input}: {note}", file=sys.stderr)
    ds = imp.dataset
    U = input_matrix(ds, spec, where=f"{args.input}: ")
    ctx = Plant(spec).create_context(seed=args.seed)
    traj = Simulator(ctx).run(ds.time - ds.time[0] + 0.0, U)
    cols = traj.dataset_columns()
    cols["time"] = ds.time
    write_dataset(args.out, cols, spec=spec)
    print(f"wrote {args.out}: {len(ds)} rows, joints {', '.join(spec.joint_names)}")
    return 0
