"""hydrohil effects: the catalog of switchable model effects."""

import json


def register(sub):
    p = sub.add_parser("effects", help="list the model effects and their parameters")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args):
    from ..effects import catalog

    cat = catalog()
    if args.json:
        print(json.dumps(cat, indent=2))
        return 0
    for e in cat:
        print(f"{e['name']} ({e['scope']}): {e['description']}")
        for p in e["parameters"]:
            print(f"    {p['name']} [{p['unit']}] default {p['default']:g}, bounds [{p['lower']:g}, {p['upper']:g}]: {p['description']}")
    return 0
