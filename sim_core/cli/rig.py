"""hydrohil rig new: a rig of your own from a template, written as editable data (robot.toml + URDF)."""


def register(sub):
    from ..rigs import TEMPLATES

    p = sub.add_parser("rig", help="describe your own rig as data: 'rig new TEMPLATE --out DIR'")
    rsub = p.add_subparsers(dest="rig_command", metavar="<rig command>")
    rsub.required = True
    n = rsub.add_parser(
        "new", help="write DIR/robot.toml and DIR/<name>.urdf from a template",
        description="Templates: " + "; ".join(f"{k}: {v}" for k, v in TEMPLATES.items())
        + ". 'hydrohil rig new TEMPLATE --knobs' lists a template's knobs.")
    n.add_argument("template", choices=list(TEMPLATES), help="rig template")
    n.add_argument("--out", help="directory to write into (created if missing)")
    n.add_argument("--name", help="robot name and URDF file name (default: the directory's name)")
    n.add_argument("--set", action="append", default=[], metavar="PATH=VALUE",
                   help="a template knob (e.g. orientation=horizontal, incline_deg=30, load_kg=250) or any key of "
                        "the written robot.toml (e.g. joints.lift.cylinder.bore=0.063); repeatable")
    n.add_argument("--force", action="store_true", help="overwrite existing files")
    n.add_argument("--knobs", action="store_true", help="list the template's knobs and exit")
    n.set_defaults(func=run_new)


def run_new(args) -> int:
    import sys

    from ..rigs import RigError, new_rig, template_knobs
    from . import CliError

    if args.knobs:
        for kn in template_knobs(args.template):
            print(f"  {kn.describe()}" + (f" [= {kn.path}]" if kn.path else ""))
        return 0
    if not args.out:
        raise CliError("--out DIR is required")
    try:
        toml_path, urdf_path, warnings = new_rig(args.template, args.out, args.name, args.set, force=args.force)
    except RigError as exc:
        raise CliError(str(exc)) from None
    print(f"wrote {toml_path} and {urdf_path}")
    for w in warnings:
        print(f"hydrohil rig: warning: {w}", file=sys.stderr)
    print(f"edit the numbers (each says its unit, typical range and how to measure it), then check: "
          f"hydrohil robots --robot {args.out}")
    return 0
