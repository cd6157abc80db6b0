"""Entry point of the ``protoduino`` command.

Each subcommand lives in its own module exposing ``HELP`` (one line),
``register(parser)`` to add its arguments and ``run(args) -> int``. Adding a
command means adding a module and its name to ``COMMANDS``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence
from types import ModuleType

from .. import __version__

#: Subcommand name -> module below protoduino.cli.
COMMANDS: dict[str, str] = {
    "gen": "gen",
    "decode": "decode",
    "ports": "ports",
    "ping": "ping",
    "servo": "servo",
    "pin": "pin",
    "info": "info",
    "monitor": "monitor",
    "flash": "flash",
    "sim": "sim",
    "demo": "demo",
    "soak": "soak",
}


def _load(module: str) -> ModuleType:
    return importlib.import_module(f"{__package__}.{module}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="protoduino",
        description="Drive an Arduino's servos and pins over a reliable serial link.",
    )
    parser.add_argument("--version", action="version", version=f"protoduino {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, module in COMMANDS.items():
        mod = _load(module)
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.register(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    try:
        rc: int = args._run(args)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # Output piped into `head` and the like: not an error.
        return 0
    return rc


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
