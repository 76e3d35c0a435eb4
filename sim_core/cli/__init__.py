"""The ``hydrohil`` command. Subcommands are plugins (entry-point group ``hydrohil.commands``):
sim_core registers its own, hil_server and web add theirs, and sim_core never imports them."""

from __future__ import annotations

import argparse
import sys
from importlib.metadata import entry_points

from ..components.base import ParameterError
from ..kernel.compile_notice import notice, on_kernel_compile


class CliError(Exception):
    """A user-facing error: printed as 'hydrohil <cmd>: error: ...' with exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hydrohil",
        description="Hardware-in-the-loop emulator for hydraulically actuated manipulators.",
    )
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    sub.required = True
    eps = sorted(entry_points(group="hydrohil.commands"), key=lambda e: e.name)
    for ep in eps:
        ep.load()(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    # SIGPIPE stays ignored (Python's default): a client that drops its socket must never kill
    # 'hydrohil serve'. A closed stdout ('hydrohil effects | head') is handled below instead.
    parser = build_parser()
    args = parser.parse_args(argv)

    def compiling():     # a first run would otherwise sit silent for minutes
        print(f"hydrohil {args.command}: {notice()}", file=sys.stderr, flush=True)

    try:
        with on_kernel_compile(compiling):
            rc = args.func(args)
    except (CliError, ParameterError, ValueError, KeyError, FileNotFoundError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        print(f"hydrohil {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0
    return int(rc or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
