"""``protoduino pwm PORT PIN DUTY``: configure a PWM output and set its duty."""

from __future__ import annotations

import argparse

from ..board import Board
from ..commands import PWM
from ..constants import PWM_MAX_DUTY
from . import argtypes
from .options import add_hold, add_port, configuring, hold, with_board

HELP = "set a PWM output's duty (0..255, as analogWrite)"

DUTY = argtypes.number(0, PWM_MAX_DUTY, name="duty")


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser)
    parser.add_argument("pin", type=argtypes.pin, metavar="PIN")
    parser.add_argument(
        "duty", type=DUTY, metavar="DUTY", help="0 (off) .. 255 (always on); rounded to a whole"
    )
    parser.add_argument("--safe", type=DUTY, default=0, help="safe duty (default: 0, off)")
    add_hold(parser, "sets the safe duty")


def run(args: argparse.Namespace) -> int:
    def body(board: Board) -> int:
        with configuring(board, args.pin, PWM):
            out = board.pwm_output(args.pin, safe=args.safe)
        out.write(args.duty)
        print(f"pwm {args.pin}: {out.value}")
        hold(board, args.hold)
        return 0

    return with_board("pwm", args, body)
