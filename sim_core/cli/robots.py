"""hydrohil robots: list the built-in robot configurations and their joints, or describe one robot
(a built-in one or your own rig) in full with --robot."""

import json


def register(sub):
    p = sub.add_parser("robots", help="list robots and their joints; --robot R describes one (yours too)")
    p.add_argument("--robot", help="describe this robot only: a built-in name, a directory holding robot.toml, "
                                   "or a robot.toml path")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args):
    from ..model.spec import available_robots
    from ..plant import Plant

    if args.robot is not None:
        return _one(args)
    robots = [Plant.from_robot(name).describe() for name in available_robots()]
    if args.json:
        print(json.dumps(robots, indent=2))
        return 0
    for r in robots:
        print(f"{r['name']}: {r['description']}")
        for j in r["joints"]:
            lo, hi = j["command_voltage_range"]
            print(f"  {j['name']:<10} {j['actuator']:<16} {'sensed' if j['sensed'] else 'unsensed':<9} {lo:g}..{hi:g} V")
        if r["passive_joints"]:
            print(f"  passive: {', '.join(r['passive_joints'])}")
    return 0


def _one(args) -> int:
    from ..model.describe import describe_robot
    from ..model.spec import load_robot

    d = describe_robot(load_robot(args.robot))
    if args.json:
        print(json.dumps(d, indent=2))
        return 0
    print(f"{d['name']}: {d['description']}")
    print(f"  from {d['source']} (URDF {d['urdf']})")
    for j in d["joints"]:
        qu = j["q_unit"]
        lo, hi = j["limits"]
        a = j["actuator"]
        kind = a["kind"] + (f" ({a['linkage']})" if "linkage" in a else f" ({a['type']})")
        sensor = (f"sensor {j['sensor']['A']:g} {qu}/V, offset {j['sensor']['B']:g} {qu}" if j["sensed"] else "not sensed")
        clo, chi = j["command_voltage_range"]
        print(f"  {j['name']:<10} {j['type']:<9} q in {qu}, limits {lo:g}..{hi:g} {qu}; {kind}; {sensor}; "
              f"command {clo:g}..{chi:g} V")
        for e in j["effects"]:
            params = ", ".join(f"{k}={v:g} {e['units'][k]}".rstrip() if isinstance(v, float) else f"{k}={v}"
                               for k, v in e["params"].items())
            print(f"    effect {e['name']}: {params}")
    if d["passive_joints"]:
        print(f"  passive: {', '.join(p['name'] for p in d['passive_joints'])}")
    for e in d["global_effects"]:
        print(f"  effect {e['name']}: {e['params']}")
    if d["estimated"]:
        print("  estimated (calibration may move them within):")
        for k, (lo, hi) in d["estimated"].items():
            print(f"    {k}: {lo:g} .. {hi:g} {d['estimated_units'].get(k, '')}".rstrip())
    return 0
