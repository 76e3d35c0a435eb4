"""hydrohil robots: list the built-in robot configurations and their joints."""

import json


def register(sub):
    p = sub.add_parser("robots", help="list robots and their joints")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args):
    from ..model.spec import available_robots
    from ..plant import Plant

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
