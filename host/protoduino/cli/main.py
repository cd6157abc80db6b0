"""Entry point of the ``protoduino`` command.

Each subcommand lives in its own module exposing ``HELP`` (one line),
``register(parser)`` to add its arguments and ``run(args) -> int``, and
optionally ``check(args) -> str | None`` for what depends on several options
(a refusal there is a usage error like any other). Adding a command means
adding a module and its name to ``COMMANDS``.

Bad values are usage errors: exit status 2 and one line on stderr, from the
argparse types in :mod:`.argtypes`, before any port is opened. Nothing the
command line does ends in a traceback (``-vv`` logs one for a bug).

The development command ``soak`` lives in the separate distribution
``protoduino-dev`` (``dev/`` in the source checkout), which a user's
``pip install protoduino`` does not carry. It declares it as an entry point
(:mod:`protoduino.plugins`); the runtime names only the command, never its
module. Without it it is still listed, and says how to get it instead of
failing with an import error. ``gen`` is the user's (:mod:`.gen`); without a
.proto it runs the development tools' generator of protoduino's own schema,
found the same way.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import NoReturn

from .. import __version__, plugins
from ..errors import ProtoduinoError
from .options import capture_check, error

log = logging.getLogger("protoduino.cli")

#: The development tools' subcommands: listed by name; their modules come by entry point.
DEV_COMMANDS = ("soak",)
DEV_MISSING = (
    "`protoduino {name}` is a development command: it works in a source checkout "
    "with the development tools installed (git clone, then ./tools/dev.sh setup, "
    "which installs the protoduino_dev package from dev/)"
)

#: Subcommand name -> its module (a development command: its entry point group).
COMMANDS: dict[str, str] = {
    "decode": f"{__package__}.decode",
    "ports": f"{__package__}.ports",
    "ping": f"{__package__}.ping",
    "servo": f"{__package__}.servo",
    "pin": f"{__package__}.pin",
    "pwm": f"{__package__}.pwm",
    "read": f"{__package__}.read",
    "watch": f"{__package__}.watch",
    "info": f"{__package__}.info",
    "outputs": f"{__package__}.outputs",
    "monitor": f"{__package__}.monitor",
    "flash": f"{__package__}.flash",
    "sim": f"{__package__}.sim",
    "demo": f"{__package__}.demo",
    "ros2": f"{__package__}.ros2",
    "console": f"{__package__}.console",
    "gen": f"{__package__}.gen",  # a user service's code; protoduino's own by entry point
    **{name: plugins.COMMANDS for name in DEV_COMMANDS},
}


class _Missing:
    """Stands in for a development command whose package is not installed."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.HELP = f"(development tools; not installed: see `protoduino {name} -h`)"

    def register(self, parser: argparse.ArgumentParser) -> None:
        parser.description = DEV_MISSING.format(name=self.name)
        # Whatever options were meant for the real command: main() lets them through.
        parser.set_defaults(_any_arguments=True)

    def run(self, args: argparse.Namespace) -> int:
        print(f"protoduino {self.name}: " + DEV_MISSING.format(name=self.name), file=sys.stderr)
        return 2


def _load(name: str, module: str) -> ModuleType | _Missing:
    if module == plugins.COMMANDS:
        entry = plugins.find(plugins.COMMANDS, name)
        if entry is None:
            return _Missing(name)
        try:
            loaded: ModuleType = entry.load()
        except ImportError:  # declared by metadata left behind, its package gone
            log.debug("development command %s does not import", name, exc_info=True)
            return _Missing(name)
        return loaded
    return importlib.import_module(module)


class Parser(argparse.ArgumentParser):
    """Usage errors in one line (the usage itself is one ``--help`` away), exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> Parser:
    parser = Parser(
        prog="protoduino",
        description="Drive an Arduino's servos and pins over a reliable serial link.",
    )
    parser.add_argument("--version", action="version", version=f"protoduino {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, module in COMMANDS.items():
        mod = _load(name, module)
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        # -v after the subcommand too; its own dest, or it would replace the count before it.
        p.add_argument(
            "-v",
            "--verbose",
            action="count",
            default=0,
            dest="verbose_after",
            help=argparse.SUPPRESS,
        )
        mod.register(p)
        p.set_defaults(_run=mod.run, _check=getattr(mod, "check", None), _parser=p)
    return parser


def _stdout_gone() -> None:
    """Stdout's reader left: what is still buffered goes nowhere, so the flush at exit
    prints no "Exception ignored" (Python's docs, signal module, "Note on SIGPIPE")."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # not a file (a test's capture)
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    os.close(devnull)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown and not getattr(args, "_any_arguments", False):
        parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    if args._check is not None and (problem := args._check(args)) is not None:
        args._parser.error(problem)
    if (problem := capture_check(args)) is not None:
        args._parser.error(problem)
    verbose = args.verbose + args.verbose_after
    level = logging.WARNING - 10 * min(verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    try:
        rc: int = args._run(args)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # Output piped into `head` and the like: not an error.
        _stdout_gone()
        return 0
    except ProtoduinoError as exc:  # a command that let one through: still one line
        return error(args.command, exc)
    except Exception as exc:  # a bug: one line, the traceback only with -vv
        log.debug("traceback", exc_info=True)
        print(
            f"protoduino {args.command}: internal error: {type(exc).__name__}: {exc} "
            "(please report it; -vv shows the traceback)",
            file=sys.stderr,
        )
        return 1
    return rc


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
