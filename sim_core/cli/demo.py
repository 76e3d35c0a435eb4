"""hydrohil demo: a short open-loop simulation, written to a CSV (what ``make run`` did before serve)."""


def register(sub):
    p = sub.add_parser("demo", help="simulate a short PRBS on the HydroLek shoulder and write out/demo.csv")
    p.add_argument("--out", default="out/demo.csv")
    p.set_defaults(func=run)


def run(args):
    from pathlib import Path

    from ..dataset import write_csv
    from ..excitation import multilevel_prbs
    from ..plant import Plant
    from ..simulator import Simulator

    plant = Plant.from_robot("hydrolek")
    t, U = multilevel_prbs(plant.spec, "j2", levels=5, amplitude=6.0, duration=10.0, rate=1000.0, seed=1)
    traj = Simulator(plant.create_context()).run(t, U)
    write_csv(args.out, traj.dataset_columns())
    print(f"simulated 10 s of hydrolek (PRBS on j2); dataset written to {Path(args.out).resolve()}")
    return 0
