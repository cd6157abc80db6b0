"""``protoduino sim``: run a simulated board in the foreground.

The board's program replaces this process (exec), so its first stdout line, the
port to connect to, is the first line the user sees, and Ctrl-C or SIGTERM
reach it directly for a clean exit. Build output goes to stderr, never stdout.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from ..errors import ProtoduinoError
from ..simboard import BACKENDS, build, command
from .options import error

HELP = "run a simulated board; prints the port to connect to first"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--backend",
        choices=sorted(BACKENDS),
        default="native",
        help="native: the firmware core on this machine (default); avr: the emulated Uno",
    )
    parser.add_argument(
        "--trace",
        type=Path,
        metavar="FILE",
        help="write one JSON line per output change: {t, pin, mode, value}",
    )
    parser.add_argument(
        "--link", type=Path, metavar="PATH", help="also make PATH a symlink to the board's port"
    )
    parser.add_argument(
        "--control",
        type=Path,
        metavar="PATH",
        help='a Unix socket driving the inputs, one JSON object per line: {"pin": 2, "level": 0}, '
        '{"pin": 14, "analog": 512}, {"pin": 3, "pulses": 100, "hz": 2000}',
    )


def run(args: argparse.Namespace) -> int:
    try:
        build(args.backend)
    except ProtoduinoError as exc:
        return error("sim", exc)
    cmd = command(args.backend, trace=args.trace, link=args.link, control=args.control)
    try:
        os.execv(cmd[0], cmd)
    except OSError as exc:
        return error("sim", f"cannot run {cmd[0]}: {exc.strerror}")
    return 0  # pragma: no cover - execv does not return
