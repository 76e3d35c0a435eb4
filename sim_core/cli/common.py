"""Helpers shared by the sim_core subcommands: loading a robot with overrides from the command line."""

from __future__ import annotations

import json

from ..model.spec import RobotSpec, SpecError, load_robot
from ..params_file import ParamsFileError, apply_params_file
from . import CliError


ROBOT_HELP = "built-in robot name, a directory holding robot.toml (e.g. from 'hydrohil rig new'), or a robot.toml path"


def parse_value(text: str):
    """Number, JSON list/bool, or plain text."""
    t = text.strip()
    try:
        return float(t)
    except ValueError:
        pass
    if t[:1] in "[{" or t in ("true", "false"):
        try:
            return json.loads(t)
        except json.JSONDecodeError:
            raise CliError(f"cannot parse value {text!r}") from None
    return t


def parse_effect(text: str) -> tuple[str, str | None, dict]:
    """'NAME:joint=J,param=value,...' -> (name, joint, params)."""
    name, _, rest = text.partition(":")
    name = name.strip()
    if not name:
        raise CliError(f"--effect {text!r}: expected NAME:joint=J,param=value")
    joint = None
    params = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, val = item.partition("=")
        if not eq or not key.strip():
            raise CliError(f"--effect {text!r}: {item!r} is not key=value")
        key = key.strip()
        if key == "joint":
            joint = val.strip()
        else:
            params[key] = parse_value(val)
    return name, joint, params


def add_model_options(p) -> None:
    p.add_argument("--effect", action="append", default=[], metavar="NAME:joint=J,param=value",
                   help="switch an effect on (repeatable); see 'hydrohil effects'")
    p.add_argument("--set", action="append", default=[], metavar="PATH=VALUE",
                   help="override a parameter, e.g. joints.j2.valve.rated_flow=3e-5 (repeatable)")
    p.add_argument("--params", metavar="FILE.toml", help="parameter/effect file (e.g. a diagnosis's extended.toml)")


def add_command_hold_option(p) -> None:
    """``--command-hold``: how a record's logged commands are replayed between samples."""
    p.add_argument("--command-hold", choices=("auto", "held", "period_mean"), default="auto",
                   help="what the valve saw between two logged commands: held (the controller or signal source ran "
                        "at the log's rate), period_mean (it ran faster, e.g. a 1 kHz PLC logged at 50 Hz, or a "
                        "joystick sampled slowly: the mean of each two samples over the period between them, every "
                        "commanded joint), or auto (default: on the joints found in closed loop, the one that fits "
                        "the record's velocity better, looked at again with the effects named)")


def load_configured_robot(args) -> RobotSpec:
    """Robot spec with --params, then --set, then --effect applied, in that order."""
    spec = load_robot(args.robot)
    try:
        if getattr(args, "params", None):
            apply_params_file(spec, args.params)
        for item in getattr(args, "set", []) or []:
            path, eq, val = item.partition("=")
            if not eq:
                raise CliError(f"--set {item!r}: expected PATH=VALUE")
            spec.set(path.strip(), parse_value(val))
        for item in getattr(args, "effect", []) or []:
            name, joint, params = parse_effect(item)
            spec.enable_effect(name, joint, **params)
    except (SpecError, ParamsFileError) as exc:
        raise CliError(str(exc)) from None
    return spec
