"""hydrohil eom: the rigid-body equations of motion M(q) qdd + C(q, qd) qd + g(q) = tau of a robot,
derived symbolically from its URDF, as LaTeX, Python or C."""

FORMATS = ("latex", "python", "c")


def register(sub):
    p = sub.add_parser("eom", help="symbolic equations of motion M(q) qdd + C(q,qd) qd + g(q) = tau (LaTeX, Python, C)")
    p.add_argument("--robot", required=True,
                   help="built-in robot name, a robot.toml, a directory holding robot.toml, or a .urdf file")
    p.add_argument("--format", required=True, choices=FORMATS, help="output language")
    p.add_argument("--out", metavar="FILE", help="write to FILE instead of standard output")
    p.set_defaults(func=run)


def _tree_and_source(robot: str):
    """The kinematic tree the simulator would build for ``robot``, and a line naming where it came from."""
    from pathlib import Path

    from ..model.spec import SpecError, load_robot
    from ..model.urdf import UrdfError, load_urdf
    from . import CliError

    path = Path(robot)
    if path.suffix.lower() == ".urdf":
        if not path.is_file():
            raise CliError(f"--robot {robot}: no such URDF file")
        try:
            return load_urdf(path), path.name
        except UrdfError as exc:
            raise CliError(f"{path}: {exc}") from None
    if path.is_dir():
        if not (path / "robot.toml").is_file():
            raise CliError(f"--robot {robot}: the directory holds no robot.toml")
        path = path / "robot.toml"
        robot = str(path)
    try:
        spec = load_robot(robot)
    except UrdfError as exc:
        raise CliError(f"--robot {robot}: its URDF: {exc}") from None
    except SpecError as exc:
        if str(exc).startswith("unknown robot"):
            raise CliError(f"{exc}; --robot also takes a robot.toml, a directory holding one, or a .urdf file") from None
        raise
    return spec.tree, f"robot {spec.name!r} ({spec.urdf_path.name})"


def _check_writable(out: str) -> None:
    """Refuse an --out that cannot be written before spending time on the derivation."""
    import os
    from pathlib import Path

    from . import CliError

    p = Path(out)
    if p.is_dir():
        raise CliError(f"--out {out}: is a directory")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise CliError(f"--out {out}: no directory {parent}")
    if not os.access(parent, os.W_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise CliError(f"--out {out}: not writable")


def run(args):
    import sys

    from ..symbolic import FORMATS as PRINTERS
    from ..symbolic import derive_equations
    from . import CliError

    if args.out:
        _check_writable(args.out)
    tree, source = _tree_and_source(args.robot)
    eom = derive_equations(tree)
    text = PRINTERS[args.format](eom, source)
    if args.out:
        try:
            with open(args.out, "w", encoding="utf-8") as fh:
                fh.write(text)
        except OSError as exc:
            raise CliError(f"--out {args.out}: cannot write: {exc.strerror or exc}") from None
    else:
        sys.stdout.write(text)
    ops = ", ".join(f"{label} {b.operation_count()}" for label, b in
                    (("M", eom.mass_matrix), ("C qd", eom.coriolis), ("g", eom.gravity_torque)))
    where = f"; wrote {args.out}" if args.out else ""
    print(f"hydrohil eom: {eom.name}: {eom.n} joints ({sum(t == 'prismatic' for t in eom.joint_types)} prismatic), "
          f"derived in {eom.derive_seconds:.2f} s; operations: {ops}{where}", file=sys.stderr)
    return 0
