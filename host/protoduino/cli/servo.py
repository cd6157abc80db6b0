"""``protoduino servo PORT PIN ANGLE``: configure a servo and move it."""

from __future__ import annotations

import argparse

from ..arguments import whole_number
from ..board import Board
from ..commands import SERVO
from ..constants import SERVO_LIMIT_MAX_US, SERVO_LIMIT_MIN_US, SERVO_MAX_DEGREES
from . import argtypes
from .options import add_hold, add_port, configuring, hold, with_board

US = argtypes.integer(SERVO_LIMIT_MIN_US, SERVO_LIMIT_MAX_US, name="microseconds")

HELP = "move a servo to ANGLE degrees (or microseconds with --us)"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser)
    parser.add_argument("pin", type=argtypes.pin, metavar="PIN")
    parser.add_argument(
        "angle",
        type=argtypes.number(name="angle"),
        metavar="ANGLE",
        help="0..180 degrees, or us with --us; a real number, rounded to a whole as "
        "Servo.write rounds (45.5 -> 46)",
    )
    parser.add_argument("--us", action="store_true", help="ANGLE is a pulse width in microseconds")
    parser.add_argument(
        "--safe",
        type=argtypes.integer(0, SERVO_MAX_DEGREES, name="degrees"),
        default=90,
        help="safe position in degrees (90)",
    )
    parser.add_argument("--min-us", type=US, default=544, help="pulse for 0 degrees (544)")
    parser.add_argument("--max-us", type=US, default=2400, help="pulse for 180 degrees (2400)")
    add_hold(parser, "returns the servo to --safe")


def check(args: argparse.Namespace) -> str | None:
    """Refused before the Init, which would move the servo to its safe position first."""
    if args.min_us >= args.max_us:
        return f"--min-us {args.min_us} must be below --max-us {args.max_us}"
    low, high = (args.min_us, args.max_us) if args.us else (0, SERVO_MAX_DEGREES)
    if not low <= _whole(args) <= high:
        unit = "us" if args.us else "degrees"
        return f"{args.angle:g} {unit} is outside {low}..{high}; nothing sent"
    return None


def _whole(args: argparse.Namespace) -> int:
    """ANGLE as the whole degrees (or us) the device gets: the API's rounding."""
    return whole_number("us" if args.us else "degrees", args.angle)


def run(args: argparse.Namespace) -> int:

    def body(board: Board) -> int:
        with configuring(board, args.pin, SERVO):
            servo = board.servo(args.pin, safe=args.safe, min_us=args.min_us, max_us=args.max_us)
        if args.us:
            servo.write_us(args.angle)
            print(f"servo {args.pin}: {_whole(args)} us")
        else:
            servo.write(args.angle)
            print(f"servo {args.pin}: {_whole(args)} degrees")
        hold(board, args.hold)
        return 0

    return with_board("servo", args, body)
