"""hydrohil import: a log file from a real rig into the dataset format, with a JSON sidecar saying
which column was what."""

SIDECAR_SUFFIX = ".import.json"


def register(sub):
    from ..ingest import add_reading_options

    p = sub.add_parser(
        "import",
        help="read a log file (any delimited text or Parquet) into a dataset CSV/Parquet for a robot",
        description="Map the columns of a log file onto the dataset columns of a robot (--column NAME=SOURCE[:UNIT]), "
                    "convert them to SI, check the time grid (jitter, gaps and repeated timestamps are reported, time "
                    "going backwards is an error), converter saturation and glitches of a position (repaired), and write the dataset (.csv or .parquet) "
                    "with OUT" + SIDECAR_SUFFIX + " beside it: the summary and notes printed here, as JSON.",
    )
    p.add_argument("raw", metavar="RAW", nargs="+",
                   help="the log file; several files are one record side by side (a logger that writes one channel "
                        "per file): row k of each is the same sample, and a later file's columns are numbered on from "
                        "the earlier files' (with a 1-column a.txt and b.txt, b.txt's column 0 is column 1)")
    p.add_argument("--robot", required=True, help="built-in robot name, a directory holding robot.toml, or a robot.toml")
    p.add_argument("--out", required=True, metavar="DATASET.csv", help="dataset to write (.csv or .parquet)")
    p.add_argument("--json", action="store_true", help="print the import report as JSON instead of text")
    add_reading_options(p)
    p.set_defaults(func=run)


def run(args):
    import json
    import sys
    from pathlib import Path

    from ..dataset import write_dataset
    from ..ingest import import_record, options_from_args
    from ..model.spec import load_robot
    from . import CliError

    spec = load_robot(args.robot)
    res = import_record(args.raw, spec, options_from_args(args))
    out = Path(args.out)
    ds = res.dataset
    sidecar = out.with_name(out.name + SIDECAR_SUFFIX)
    report = res.to_dict()
    report["dataset"] = str(out)
    try:
        write_dataset(out, {c: ds.data[:, i] for i, c in enumerate(ds.columns)}, spec=spec)
        sidecar.write_text(json.dumps(report, indent=2) + "\n")
    except OSError as exc:
        raise CliError(f"{exc.filename or out}: cannot write ({exc.strerror})") from None
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    for line in res.summary_lines():
        print(line)
    if res.notes:
        print("notes:")
        for n in res.notes:
            print(f"  {n}")
    print(f"wrote {out} and {sidecar}", file=sys.stdout)
    return 0
