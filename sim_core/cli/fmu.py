"""hydrohil fmu: export the plant as an FMI 2.0 co-simulation FMU (Simulink, OpenModelica, FMPy)."""


def register(sub):
    from .common import ROBOT_HELP, add_model_options

    p = sub.add_parser("fmu", help="export the plant as an FMI 2.0 co-simulation FMU (needs the 'fmu' extra)",
                       description="Write the plant of a robot, with any --params/--set/--effect changes, as an "
                                   "FMI 2.0 co-simulation FMU: inputs u_<joint> (V); outputs q_<joint> (measured), "
                                   "qd_<joint> (true velocity), p_<joint>_a/_b (Pa); every numeric parameter. The "
                                   "FMU runs the plant in Python: the importing side needs hydrohil installed.")
    p.add_argument("--robot", required=True, help=ROBOT_HELP)
    p.add_argument("--out", required=True, metavar="PLANT.fmu", help="the FMU file to write")
    add_model_options(p)
    p.set_defaults(func=run)


def run(args):
    from ..export.fmu_build import build_fmu
    from ..export.fmu_variables import interface
    from ..model.spec import load_robot
    from .common import load_configured_robot

    spec = load_configured_robot(args)
    base = load_robot(args.robot)
    sources = [f"--params {args.params}"] if args.params else []
    sources += [f"--set {s}" for s in args.set] + [f"--effect {e}" for e in args.effect]
    out = build_fmu(spec, args.out, base=base, sources=", ".join(sources))
    counts = {c: sum(v.causality == c for v in interface(spec)) for c in ("input", "output", "parameter")}
    print(f"wrote {out}: FMI 2.0 co-simulation FMU of {spec.name}, {counts['input']} inputs, {counts['output']} outputs, "
          f"{counts['parameter']} parameters; the importing side needs a Python with hydrohil installed")
    return 0
