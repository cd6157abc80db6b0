"""``protoduino pin PORT PIN on|off``: configure a digital output and set it."""

from __future__ import annotations

import argparse

from ..board import Board
from ..commands import DIGITAL
from . import argtypes
from .options import add_hold, add_port, configuring, hold, with_board

HELP = "set a digital output pin on or off"

LEVELS = {"on": True, "off": False, "1": True, "0": False, "high": True, "low": False}


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser)
    parser.add_argument("pin", type=argtypes.pin, metavar="PIN")
    parser.add_argument("level", choices=sorted(LEVELS), metavar="on|off")
    parser.add_argument(
        "--safe", choices=sorted(LEVELS), default="off", help="safe level (default: off)"
    )
    add_hold(parser, "sets the safe level")


def run(args: argparse.Namespace) -> int:
    def body(board: Board) -> int:
        with configuring(board, args.pin, DIGITAL):
            out = board.digital_output(args.pin, safe=LEVELS[args.safe])
        level = LEVELS[args.level]
        out.write(level)
        print(f"pin {args.pin}: {'on' if level else 'off'}")
        hold(board, args.hold)
        return 0

    return with_board("pin", args, body)
