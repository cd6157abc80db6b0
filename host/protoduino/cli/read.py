"""``protoduino read PORT PIN``: configure an input and print its value once."""

from __future__ import annotations

import argparse

from ..board import Board
from . import argtypes
from .inputs import add_input_options, configure, default_kind, show
from .options import add_port, error, with_board

HELP = "read an input once: a digital level (or --analog counts, or a --counter's count)"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser)
    parser.add_argument("pin", type=argtypes.pin, metavar="PIN")
    add_input_options(parser)


def run(args: argparse.Namespace) -> int:
    def body(board: Board) -> int:
        kind = default_kind(args)
        source = configure(board, args.pin, kind, args)
        reading = source.reading()
        if reading is None:  # its report was lost on the line
            return error("read", f"pin {args.pin}: the device reported no value in time")
        print(show(kind, reading, as_json=args.json))
        return 0

    return with_board("read", args, body)
